"""``rtdenoise``: the reference's own shadow rays (1-8 per pixel, closest hit), then a denoiser.

The rays against the reference's, bit for bit; the blocker distance against the geometry (the
nearest of two blockers, through a cutout, through instances); noise decorrelated between pixels;
each denoiser against the reference where a depth discontinuity separates two shadowed receivers
(and a denoiser made blind to depth bleeding there, so the check can fail); tiles skipped only
where all is lit or in umbra; the hard cases (a point light, a light straddling a wall, a NaN, a
bake, an instanced stage, several pixel samples); bad parameters as one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import add_box, add_camera, add_quad, add_rect_light, make_stage, scene_path

import wsoft
from wsoft.errors import ParameterError
from wsoft.techniques import create


def render(scene, configs, device="cpu", w=64, h=48, **kw):
    return wsoft.render(scene, configs, width=w, height=h, device=device, **kw)


# --------------------------------------------------------------------------- rays


@pytest.mark.parametrize("stage", ["box_plane.usda", "cutout.usda", "multi_light.usda"])
def test_the_rays_are_the_references(device, stage):
    """``denoiser=none`` is the reference's estimator on the reference's rays: equal bit for bit to
    ``reference samples=N traversal=ray`` with the same seed, for every light kind, through cutouts."""
    scene = wsoft.load_scene(scene_path(stage))
    for light in [l.path for l in scene.lights] if stage == "multi_light.usda" else [None]:
        for n in (1, 2, 8):
            fs = render(scene, [("rtdenoise", {"denoiser": "none", "samples": n, "seed": 3}),
                                ("reference", {"samples": n, "seed": 3, "traversal": "ray"})], device, light=light)
            a, b = (fs[k].V for k in fs)
            assert np.array_equal(a, b), (stage, light, n, int((a != b).sum()))
            assert ((a > 0) & (a < 1)).sum() > 0 or n == 1


def trace(scene, samples=1, w=64, h=48, device="cpu"):
    """The rays' estimate (:class:`~wsoft.techniques.rtdenoise.RayEstimate`) and the G-buffer of a frame."""
    from wsoft.pipeline import build_graph, execute

    built = build_graph(scene, create("rtdenoise", {"samples": samples}), width=w, height=h, device=device)
    keys = [k for k in built.ctx.graph.producers if k.kind in ("rtdenoise_rays", "gbuffer")]
    res, _, _ = execute(built, device, extra=keys)
    est = next(res[k] for k in keys if k.kind == "rtdenoise_rays")
    gb = next(res[k] for k in keys if k.kind == "gbuffer")
    return est, gb


def layered_stage(lower_transparent: bool):
    """A ground under two parallel plates (z = 1 and z = 2) and a small rect light at z = 4; with
    ``lower_transparent`` the lower plate is a cutout whose constant opacity is below its threshold."""
    from pxr import Sdf

    from wsoft.stages.builders import add_material, bind

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    add_quad(st, "/World/Lower", (0, 0, 1), 0.8)
    add_quad(st, "/World/Upper", (0, 0, 2), 0.8)
    if lower_transparent:
        mat = add_material(st, "/World/Looks/Clear", (0.5, 0.5, 0.5))
        sh = st.GetPrimAtPath("/World/Looks/Clear/PreviewSurface")
        from pxr import UsdShade

        UsdShade.Shader(sh).CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(0.0)
        UsdShade.Shader(sh).CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)
        bind(st.GetPrimAtPath("/World/Lower"), mat)
    add_rect_light(st, "/World/L", (0, 0, 4), 0.4, 0.4)
    add_camera(st, "/World/Cam", (0, -5, 5), (0, 0, 0))
    return wsoft.load_scene(st)


def trace_points(scene, points, samples, device="cpu"):
    """The rays' estimate at given ground points (normals up), through a bake G-buffer."""
    from wsoft.raster.gbuffer import bake_gbuffer
    from wsoft.scene.device import upload_scene
    from wsoft.techniques.rtdenoise import trace_estimate

    pts = np.asarray(points, np.float32)
    gb = bake_gbuffer(pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1)), np.zeros(len(pts), np.int32), None, device)
    light = scene.lights[0]
    from wsoft.lightspace.light import light_gpu

    est = trace_estimate(upload_scene(scene, device), light_gpu(light, scene.diagonal), light, gb, samples, 0, 1.0)
    n = len(pts)
    return est.hit.numpy()[:n], est.blocked.numpy()[:n], est.traced.numpy()[:n]


@pytest.mark.parametrize("lower_transparent", [False, True])
def test_the_blocker_distance_is_the_nearest_blocker(device, lower_transparent):
    """Two plates (half side 0.8) at z = 1 and z = 2 over the ground, a 0.4 x 0.4 light at z = 4.
    Ground points under the middle (|x|, |y| <= 0.4) keep the distance to the lower plate (a closest
    hit: the upper one blocks those rays too), or with the lower plate cut out everywhere to the
    upper one (alpha-tested); points at x = 1.2, whose rays pass beside the lower plate, keep the
    upper one's. Each distance lies between the plate's height and that height over the steepest
    ray's cosine."""
    scene = layered_stage(lower_transparent)
    g = np.linspace(-0.4, 0.4, 9)
    middle = [(x, y, 0.0) for x in g for y in g]
    beside = [(1.2, y, 0.0) for y in g]
    hit, blocked, traced = trace_points(scene, middle + beside, 8, device)
    assert np.all(traced == 8) and np.all(blocked == 8)

    def within(h, offset):  # offset: the largest horizontal distance from a point to a light point, per axis
        return h * (1 - 1e-4), h * np.sqrt(1 + (np.sqrt(2) * offset / 4) ** 2) * (1 + 1e-4)

    lo, hi = within(2.0 if lower_transparent else 1.0, 0.4 + 0.2)
    m = hit[: len(middle)]
    assert m.min() >= lo and m.max() <= hi, (m.min(), m.max(), lo, hi)
    lo, hi = within(2.0, 1.2 + 0.2)
    b = hit[len(middle):]
    assert b.min() >= lo and b.max() <= hi, (b.min(), b.max(), lo, hi)
    est, _ = trace(scene, samples=2, device=device)
    assert np.all(est.hit.numpy()[est.blocked.numpy() == 0] == -1.0)


def test_the_penumbra_radius_follows_the_blocker(device):
    """On ``box_plane`` (a 1 x 1 light at height 3, the occluder at height 1) every blocked ground
    ray has d / (D - d) close to 1/2, so the radius d tan(a) / 2 with tan a = 0.5 / (D - d) is
    close to 1/8: a quarter of the 1/2-unit penumbra."""
    est, gb = trace(wsoft.load_scene(scene_path("box_plane.usda")), samples=2, device=device)
    pos, pen, blocked = gb.pos.numpy(), est.pen.numpy(), est.blocked.numpy()
    ground = (gb.prim.numpy() >= 0) & (np.abs(pos[:, 2]) < 1e-3) & (blocked > 0)
    assert ground.sum() > 50
    assert np.allclose(pen[ground], 0.125, rtol=0.01), (pen[ground].min(), pen[ground].max())


def test_instances_are_traced_as_the_flat_scene(device):
    """Closest-hit rays go through the instances' top level: the raw estimate and its blocker
    distances equal the flattened scene's; the denoised V too, to float rounding of the G-buffer."""
    from instancing_util import rot, split, xf

    placements = [(0, xf()), (0, xf(rot((0, 0, 1), 0.5), (0.6, 0.3, 0.4), (0.7, 0.7, 1))), (1, xf(t=(-0.8, 0.5, 0.3))),
                  (1, xf(rot((1, 0, 0), 0.3), (0.9, -0.7, 0.6), (-1, 1, 1)))]
    inst, flat = split(wsoft.load_scene(scene_path("cutout.usda")), ["Fence", "Leaf"], placements)
    ea, _ = trace(inst, samples=2, device=device)
    eb, _ = trace(flat, samples=2, device=device)
    assert np.array_equal(ea.vis.numpy(), eb.vis.numpy())
    np.testing.assert_allclose(ea.hit.numpy(), eb.hit.numpy(), rtol=1e-4, atol=1e-5)
    assert (ea.blocked.numpy() > 0).sum() > 200
    a = render(inst, "rtdenoise", device, w=96, h=72)
    b = render(flat, "rtdenoise", device, w=96, h=72)
    assert a.stats["scene"]["instancing"]["mode"] == "kept"
    assert np.abs(a.V - b.V).max() < 1e-3


def test_noise_is_decorrelated_between_pixels(device):
    """One ray per pixel in a wide penumbra: the residual against the reference is uncorrelated
    between neighbouring pixels (each receiver draws its own light sample), the same seed repeats
    it exactly, another seed changes it."""
    scene = wsoft.load_scene(scene_path("penumbra_ramp.usda"))
    fs = render(scene, [("rtdenoise", {"denoiser": "none", "samples": 1}), ("reference", {"samples": 256})], device, w=128, h=96)
    raw, ref = fs["rtdenoise"].V.astype(np.float64), fs["reference"].V.astype(np.float64)
    pen = (ref > 0.1) & (ref < 0.9)
    assert pen.sum() > 200
    r = np.where(pen, raw - ref, np.nan)
    for dx, dy in ((1, 0), (0, 1), (1, 1)):
        a, b = r[: r.shape[0] - dy, : r.shape[1] - dx], r[dy:, dx:]
        ok = np.isfinite(a) & np.isfinite(b)
        c = np.corrcoef(a[ok], b[ok])[0, 1]
        assert ok.sum() > 100 and abs(c) < 0.15, (dx, dy, c)
    again = render(scene, ("rtdenoise", {"denoiser": "none", "samples": 1}), device, w=128, h=96)
    other = render(scene, ("rtdenoise", {"denoiser": "none", "samples": 1, "seed": 1}), device, w=128, h=96)
    assert np.array_equal(again.V, raw.astype(np.float32))
    assert (other.V != again.V)[pen].mean() > 0.3


# --------------------------------------------------------------------------- denoisers


@pytest.mark.parametrize("denoiser", ["penumbra", "atrous"])
def test_each_denoiser_brings_the_raw_rays_near_the_reference(device, denoiser):
    """On ``penumbra_ramp`` at 320 x 240, each denoiser at its defaults cuts the raw 2-ray
    estimate's penumbra MAE at least threefold (measured 0.179 raw, 0.040 penumbra, 0.048 atrous)."""
    scene = wsoft.load_scene(scene_path("penumbra_ramp.usda"))
    res = wsoft.compare(scene, [("rtdenoise", {"denoiser": "none"}), ("rtdenoise", {"denoiser": denoiser})], samples=256, width=320,
                        height=240, device=device)
    raw = res["rtdenoise(denoiser=none)"].stats["error"]
    den = res["rtdenoise" if denoiser == "penumbra" else "rtdenoise(denoiser=atrous)"].stats["error"]
    assert raw["penumbra_pixels"] > 300
    assert den["mae_penumbra"] * 3 < raw["mae_penumbra"], (den["mae_penumbra"], raw["mae_penumbra"])
    assert den["mae"] < raw["mae"]


def two_depths_stage():
    """Seen from straight above: a plate A at z = 2 (4 x 3) over a ground B at z = 0; a bar at z = 3
    (x in [1.5, 2.5], across the whole view in y) under a sun 45 degrees off (from +x, a 10 degree
    cone) shadows a band on A (x in [0.5, 1.5], d = 1.4) and a band on B (x in [-1.5, -0.5], d =
    4.2, a penumbra three times as wide). Across A's long edges A's umbra meets B's light and A's
    light meets B's umbra."""
    from wsoft.stages.builders import add_sun

    st = make_stage()
    add_quad(st, "/World/B", (0, 0, 0), 6)
    add_box(st, "/World/A", (-2, -1.5, 1.95), (2, 1.5, 2.0))
    add_box(st, "/World/Bar", (1.5, -8, 3.0), (2.5, 8, 3.05))
    add_sun(st, "/World/Sun", 10.0, toward=(1, 0, 1))
    add_camera(st, "/World/Cam", (0, 0, 10), (0, 0, 0), up=(0, 1, 0), focal=30.0)
    return wsoft.load_scene(st)


def window(a: np.ndarray, r: int, fill: float, how) -> np.ndarray:
    """``how`` (np.min or np.max) of ``a`` over the (2r + 1)^2 window about each pixel."""
    from numpy.lib.stride_tricks import sliding_window_view

    return how(sliding_window_view(np.pad(a, r, constant_values=fill), (2 * r + 1, 2 * r + 1)), axis=(2, 3))


def across_the_step(ref: np.ndarray, f, r: int = 3) -> dict:
    """Pixels where only the other receiver could change the answer: within ``r`` pixels every
    pixel of its own receiver has the same reference class (umbra <= 0.01, lit >= 0.99) and some
    pixel of the other receiver the opposite one."""
    on_a = (f["A"] > 0) & (np.abs(f["P.Z"] - 2.0) < 0.01)
    on_b = (f["A"] > 0) & (np.abs(f["P.Z"]) < 0.01)
    out = {}
    for name, me, other in (("A", on_a, on_b), ("B", on_b, on_a)):
        out[f"{name} umbra"] = me & (window(np.where(me, ref, -1.0), r, -1.0, np.max) < 0.01) & (
            window(np.where(other, ref, -1.0), r, -1.0, np.max) > 0.99)
        out[f"{name} lit"] = me & (window(np.where(me, ref, 2.0), r, 2.0, np.min) > 0.99) & (
            window(np.where(other, ref, 2.0), r, 2.0, np.min) < 0.01)
    return out


@pytest.mark.parametrize("denoiser,blind", [("penumbra", {"plane_sensitivity": 1.0}), ("atrous", {"sigma_z": 100.0})])
def test_no_blur_across_a_depth_discontinuity(device, denoiser, blind):
    """Next to plate A's silhouette, where A's umbra meets B's light and A's light meets B's umbra
    (pixels whose own receiver is all umbra or all lit within 3 pixels, the other receiver the
    opposite), the denoised V stays the reference's (measured: exactly for ``penumbra``, within
    0.015 for ``atrous``); the same denoiser made blind to depth (a tangent-plane tolerance of the
    whole frustum; a depth weight 100 times as tolerant) bleeds one receiver's shadow onto the other
    there (measured 0.36 and 0.32 at worst)."""
    scene = two_depths_stage()
    cfg = [("rtdenoise", {"denoiser": denoiser}), ("rtdenoise", {"denoiser": denoiser, **blind}), ("reference", {"samples": 256})]
    fs = render(scene, cfg, device, w=96, h=72)
    good, bad, ref = (fs[k].V for k in fs)
    sets = across_the_step(ref, fs["reference"])
    assert all(m.sum() >= 20 for m in sets.values()), {k: int(m.sum()) for k, m in sets.items()}  # every meeting is in view
    sure = np.logical_or.reduce(list(sets.values()))
    assert np.abs(good - ref)[sure].max() < 0.05, np.abs(good - ref)[sure].max()
    assert np.abs(bad - ref)[sure].max() > 0.2  # the check can fail


def test_tiles_all_lit_or_in_umbra_are_skipped(device):
    """Tiles (16 x 16) whose raw samples are all 1 or all 0, with no mixed tile next to them (the
    penumbrae here are narrower than a tile: a mixed tile reaches its neighbours only), keep the
    raw estimate; the skipped tiles and their samples are counted; a frame with no
    blocker skips every tile and gives V = 1 everywhere."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    fs = render(scene, [("rtdenoise", {}), ("rtdenoise", {"denoiser": "none"})], device, w=96, h=72)
    den, raw = fs["rtdenoise"], fs["rtdenoise(denoiser=none)"]
    c = den.counters(den.stats["light_labels"][0])
    assert 0 < c["tiles_skipped"] < c["tiles"] and c["samples_skipped"] > 0
    covered = raw["A"] > 0
    t = 16
    tiles = np.zeros((72 // t + 1, 96 // t), int)  # 0 mixed, 1 all lit, 2 all umbra
    for ty in range(tiles.shape[0]):
        for tx in range(tiles.shape[1]):
            v = raw.V[ty * t:(ty + 1) * t, tx * t:(tx + 1) * t][covered[ty * t:(ty + 1) * t, tx * t:(tx + 1) * t]]
            tiles[ty, tx] = 1 if np.all(v == 1.0) else 2 if np.all(v == 0.0) else 0
    quiet = window(np.where(tiles == 0, 0, 1).astype(float), 1, 1.0, np.min) == 1  # no mixed neighbour
    mask = np.repeat(np.repeat(quiet, t, 0), t, 1)[:72, :96] & covered
    assert mask.sum() > 500 and mask.sum() <= c["samples_skipped"]
    assert np.array_equal(den.V[mask], raw.V[mask])
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 3)
    add_rect_light(st, "/World/L", (0, 0, 3), 1, 1)
    add_camera(st, "/World/Cam", (0, -4, 3), (0, 0, 0))
    f = render(wsoft.load_scene(st), "rtdenoise", device, w=48, h=36)
    c = f.counters("L")
    assert c["tiles_skipped"] == c["tiles"] and c["rays_blocked"] == 0
    assert np.all(f.V[f["A"] > 0] == 1.0)


# --------------------------------------------------------------------------- hard cases


def test_a_point_light_is_the_hard_shadow(device):
    """A point light has no penumbra: every ray goes to the centre, nothing is blurred, and V is the
    one-ray reference exactly."""
    from wsoft.stages.builders import add_point_light

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 3)
    add_box(st, "/World/B", (-0.5, -0.5, 0.5), (0.5, 0.5, 1.0))
    add_point_light(st, "/World/P", (0.3, 0.2, 3))
    add_camera(st, "/World/Cam", (0, -4, 4), (0, 0, 0))
    fs = render(wsoft.load_scene(st), [("rtdenoise", {}), ("rtdenoise", {"denoiser": "atrous"}), ("reference", {"samples": 1})], device)
    den, at, ref = (fs[k].V for k in fs)
    assert ((ref == 0) & (fs["reference"]["A"] > 0)).sum() > 100
    assert np.array_equal(den, ref)
    # SVGF's spatial variance is not zero along a hard edge: the à-trous steps soften it (measured 0.019)
    assert np.abs(at - ref).mean() < 0.03


def test_a_light_straddling_a_wall_counts_its_front_part(device):
    """The horizon: every wall point has 3/8 of the light in front of it (tests/test_horizon.py's
    wall), no blocker: the denoised V is exactly the front fraction although one ray per pixel
    mostly leaves behind the wall (its part in front is estimated, the front fraction is exact)."""
    from test_horizon import _wall_under_light

    f = render(_wall_under_light(), ("rtdenoise", {"samples": 1}), device, w=32, h=24)
    wall = f["A"] > 0
    assert wall.sum() > 150
    assert np.allclose(f.V[wall], 0.375, atol=1e-6), (f.V[wall].min(), f.V[wall].max())
    raw = render(_wall_under_light(), ("rtdenoise", {"samples": 1, "denoiser": "none"}), device, w=32, h=24)
    assert set(np.unique(raw.V[wall])) == {0.0, 1.0}  # the raw estimate: a ray behind the wall, or one in front


def test_a_nan_is_never_hidden():
    """A NaN in the rays' estimate stays a NaN through both filters (and their clamp to [0, 1])."""
    import warp as wp

    from wsoft.accel.denoise import atrous_filter, penumbra_filter
    from wsoft.raster.camera import camera_gpu
    from wsoft.pipeline import frame_setup

    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    est, gb = trace(scene, samples=2)
    frac = est.frac.numpy()
    i = int(np.nonzero((frac > 0) & (frac < 1))[0][0])
    frac[i] = np.nan
    bad = wp.array(frac, dtype=float, device="cpu")
    cam = camera_gpu(frame_setup(scene, 64, 48).camera)
    a = atrous_filter(gb, bad, 3, 1.0, 128.0, 4.0, "cpu").numpy()
    b = penumbra_filter(gb, cam, bad, est.pen, tile=16, taps=8, max_radius=32.0, sharp_below=0.5, plane_sensitivity=0.02, seed=0,
                        device="cpu").numpy()
    assert np.isnan(a[i]) and np.isnan(b[i])


def test_several_pixel_samples_and_an_orthographic_camera(device):
    """Each pixel sample's layer is filtered on its own; an orthographic camera's pixel has one size."""
    from pxr import UsdGeom

    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = render(scene, "rtdenoise", device, w=48, h=36, pixel_samples=2)
    assert np.isfinite(f.V).all() and ((f.V > 0.05) & (f.V < 0.95)).sum() > 10
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 3)
    add_box(st, "/World/B", (-0.5, -0.5, 1.0), (0.5, 0.5, 1.05))
    add_rect_light(st, "/World/L", (0, 0, 3), 1, 1)
    cam = add_camera(st, "/World/Cam", (0, 0, 6), (0, 0, 0), up=(0, 1, 0))
    UsdGeom.Camera(cam.GetPrim()).CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    fs = wsoft.compare(wsoft.load_scene(st), "rtdenoise", samples=256, width=96, height=72, device=device)
    e = fs["rtdenoise"].stats["error"]
    assert e["penumbra_pixels"] > 100 and e["mae_penumbra"] < 0.1, e


def test_a_bake_needs_the_raw_rays():
    """A bake point has no pixel neighbours: the denoisers are refused with the reason, the raw
    rays bake."""
    t = create("rtdenoise", {})
    assert "denoiser=none" in t.bake_support() and "\n" not in t.bake_support()
    assert create("rtdenoise", {"denoiser": "none"}).bake_support() is None


# --------------------------------------------------------------------------- parameters


@pytest.mark.parametrize("params,match", [
    ({"samples": 0}, "samples"), ({"samples": 9}, "samples"), ({"denoiser": "bilateral"}, "denoiser"), ({"tile": 12}, "tile"),
    ({"iterations": 6}, "iterations"), ({"iterations": 2}, "iterations"), ({"radius_scale": float("nan")}, "radius_scale"),
    ({"sigma_l": float("inf")}, "sigma_l"), ({"taps": 65}, "taps"), ({"sharp_below": 0.0}, "sharp_below"),
    ({"plane_sensitivity": 2.0}, "plane_sensitivity"), ({"bogus": 1}, "no parameter bogus"), ({"samples": 1.5}, "samples"),
])
def test_bad_parameters_are_one_line_errors(params, match):
    with pytest.raises(ParameterError, match=match) as exc:
        create("rtdenoise", params)
    assert "\n" not in str(exc.value)


def test_a_bad_parameter_on_the_command_line_exits_2(tmp_path):
    from conftest import wsoft_cli

    r = wsoft_cli("render", scene_path("box_plane.usda"), "-t", "rtdenoise", "--set", "denoiser=blur", "--width", "8", "--height", "6",
                  "--out", str(tmp_path / "never.exr"))
    assert r.returncode == 2 and "denoiser 'blur' is not one of penumbra, atrous, none" in r.stderr
    assert len([ln for ln in r.stderr.splitlines() if ln.strip()]) == 1
