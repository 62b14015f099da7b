"""ESSM (Shen, Feng & Yang) and VSSM: exactness, stability and their hard cases."""

import math

import numpy as np
import pytest
from conftest import box_plane_ground_error, scene_path

import wsoft
from wsoft.errors import ParameterError
from wsoft.pipeline import build_graph
from wsoft.stages.essm_cases import essm_contact_box, essm_nonplanar
from wsoft.techniques import create
from wsoft.techniques.essm import optimal_exponent


def _ground_error(f):
    return box_plane_ground_error(f, min_penumbra=200)


@pytest.mark.parametrize("params", [{}, {"sat": "uint32"}, {"level": 2, "build": "scan"}])
def test_essm_parallel_rectangles_exact(device, params):
    """A square occluder parallel to a square light and the ground: against the exact visible
    fraction. The penumbra kernel is an ellipse (the paper's Gaussian), not the light's square,
    so the penumbra carries a shape error: MAE < 0.002, penumbra MAE < 0.03, max < 0.1."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "essm", width=128, height=96, device=device, **params)
    mae, mae_pen, mx = _ground_error(f)
    assert mae < 0.002 and mae_pen < 0.03 and mx < 0.1


def test_vssm_parallel_rectangles_exact(device):
    """VSSM's ideal case (one planar occluder): penumbra MAE < 0.015."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    for sat in ("float32", "tiles"):
        f = wsoft.render(scene, "vssm", width=128, height=96, device=device, sat=sat)
        mae, mae_pen, mx = _ground_error(f)
        assert mae < 0.001 and mae_pen < 0.015 and mx < 0.05


@pytest.mark.slow
def test_no_inf_or_nan_at_optimal_c_4096_contact():
    """At the optimal exponent with a 4096² map on the contact scene, for every SAT storage:
    the bases, the SATs and the output are finite (the float32 SAT's corner holds N² e^R)."""
    scene = wsoft.load_scene(scene_path("contact.usda"))
    for storage in ("tiles", "uint32", "float32"):
        tech = create("essm", {"shadow_map_size": 4096, "sat": storage, "build": "scan"})
        built = build_graph(scene, tech, width=48, height=36, device="cpu")
        res, _ = built.ctx.graph.execute(built.requested, "cpu", keep=["essm_basis[Light]@4096" + ("" if storage == "tiles" else f"{{sat={storage}}}"),
                                                                      "essm_sat[Light]@4096" + ("{build=scan}" if storage == "tiles" else f"{{sat={storage},build=scan}}")])
        basis = next(v for k, v in res.items() if k.kind == "essm_basis")
        sat = next(v for k, v in res.items() if k.kind == "essm_sat")
        assert basis.c == pytest.approx(optimal_exponent(storage, 20, 4096))
        assert np.isfinite(basis.basis.numpy()).all()
        data = sat.data.numpy()
        assert np.isfinite(data.astype(np.float64)).all()
        if storage == "float32":
            assert data.max() < np.finfo(np.float32).max
        v = res["channels[essm]"]["V"]
        assert np.isfinite(v).all() and v.min() >= 0.0 and v.max() <= 1.0
        assert built.ctx.counters["techniques"]["essm"]["Light"]["c_normalised"] == basis.c


def test_optimal_exponent():
    """Integer storage: μ ln 2 (§6.2/§7). float32 (not in the paper): the corner sums n² e^R stay
    within the 24-bit mantissa at unit resolution, R = 24 ln 2 − 2 ln n (at least 1), far below the
    overflow bound that was used before (74.2 at 1024²)."""
    assert optimal_exponent("tiles", 20, 1024) == pytest.approx(20 * math.log(2))
    for n in (256, 1024, 2048, 4096):
        r = optimal_exponent("float32", 20, n)
        assert r == pytest.approx(max(24 * math.log(2) - 2 * math.log(n), 1.0))
        assert n * n * math.exp(r) <= max(2.0**24, n * n * math.e) * (1 + 1e-9)
        assert n * n * math.exp(r) < float(np.finfo(np.float32).max)


def _tilted_ground(occluder):
    from pxr import Gf, UsdGeom

    from wsoft.stages import add_camera, add_quad, add_rect_light, make_stage

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 4)
    UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/G")).SetRotate(Gf.Vec3f(35, 0, 0))
    if occluder == "side":
        add_quad(st, "/World/Occ", (3, 3, 2.5), 0.3)  # beside the view: the ground is all lit
        add_rect_light(st, "/World/L", (0, 0, 4), 1, 1)
    else:
        add_quad(st, "/World/Occ", (0, 0, 1.5), 0.8)  # over the ground: a wide penumbra on a tilted receiver
        add_rect_light(st, "/World/L", (0, 0, 4), 2, 2)
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return wsoft.load_scene(st)


def test_pcf_fallback_compares_at_texel_centres(device):
    """The 2x2 PCF of a non-planar sub-kernel compares each texel's depth with
    the receiver plane at that texel's centre. At the sample point (up to half a texel away) a
    tilted, fully lit ground shadowed itself in stripes: min V 0.67 and 8.5% of the lit pixels
    below 0.99 (a bias of 0.002 forces the fallback on every lit kernel)."""
    s = _tilted_ground("side")
    ref = wsoft.render(s, "reference", width=64, height=48, device=device, samples=16)
    f = wsoft.render(s, "essm", width=64, height=48, device=device, shadow_map_size=512, bias=0.002)
    lit = (ref["A"] > 0) & (ref.V == 1.0)
    assert lit.sum() > 2000 and f.counters()["pcf_fallbacks_per_sample"] > 5  # the fallback really ran
    assert f.V[lit].min() > 0.9 and np.mean(f.V[lit] < 0.99) < 0.05


def test_every_kernel_is_micro_subdivided(device):
    """§5.2: every kernel is cut into n x n sub-kernels and each classified.
    Subdividing only kernels whose own value exceeds 1 + ε misses those whose inflated lit texels
    (a tilted receiver) and leaking occluded ones average below it: on a tilted ground under a
    wide penumbra its penumbra MAE is 0.046 against 0.027."""
    s = _tilted_ground("over")
    fs = wsoft.compare(s, [("essm", {"shadow_map_size": 512}), ("essm", {"shadow_map_size": 512, "subdivide": "flagged"})],
                       samples=256, width=96, height=72, device=device)
    a, b = fs["essm(shadow_map_size=512)"], fs["essm(shadow_map_size=512,subdivide=flagged)"]
    always, flagged = a.stats["error"], b.stats["error"]
    assert always["penumbra_pixels"] > 1000
    assert always["mae_penumbra"] < 0.75 * flagged["mae_penumbra"] and always["mae"] < flagged["mae"]
    assert a.counters()["lookups_per_sample"] > b.counters()["lookups_per_sample"]


def test_default_bias_keeps_lit_planar_kernels_planar(device):
    """e^{c bias} < 1 + ε. With the paper's μ = 20 (c = 13.9) a bias of 0.002
    gives e^{c bias} = 1.028 > 1.02: every lit planar kernel falls back to PCF (9 per sample on
    box_plane). The default bias, ln(1 + ε)/(2c), leaves no fallback there."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "essm", width=96, height=72, device=device)
    c = f.counters()
    assert math.exp(c["c_normalised"] * c["bias_normalised"]) < 1.02
    assert c["pcf_fallbacks_per_sample"] == 0.0
    old = wsoft.render(scene, "essm", width=96, height=72, device=device, bias=0.002)
    assert old.counters()["pcf_fallbacks_per_sample"] > 5


def test_float32_sat_exponent_from_its_mantissa(device):
    """A float32 SAT at the overflow exponent (74.2 at 1024²) turns small kernels
    into noise (box_plane MAE 0.021, ogre 0.77); with R from the mantissa the error is that of a
    soft exponent (MAE < 0.005 on box_plane)."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    fs = wsoft.compare(scene, [("essm", {"sat": "float32"})], samples=64, width=96, height=72, device=device)
    f = fs["essm"]
    assert f.counters()["c_normalised"] == pytest.approx(24 * math.log(2) - 2 * math.log(1024))
    assert f.stats["error"]["mae"] < 0.005


def test_contact_umbra_stays_dark(device):
    """A cube standing on the ground: over the reference's umbra (V < 0.02) ESSM's mean V is
    below 0.02 and its 95th percentile below 0.06; the only pixels above 0.2 lie on the contact
    line itself (within 0.02 of the cube's base)."""
    sc = wsoft.load_scene(essm_contact_box())
    ref = wsoft.render(sc, "reference", width=160, height=160, samples=256, device=device)
    f = wsoft.render(sc, "essm", width=160, height=160, device=device)
    umbra = (ref["A"] > 0) & (np.abs(ref["P.Z"]) < 1e-3) & (ref.V < 0.02)
    assert umbra.sum() > 150
    v = f.V[umbra]
    assert v.mean() < 0.02 and np.percentile(v, 95) < 0.06
    dist = np.maximum(np.maximum(np.abs(f["P.X"][umbra]), np.abs(f["P.Y"][umbra])) - 0.5, 0.0)
    assert np.all(dist[v > 0.2] < 0.02)


def test_nonplanar_kernel_micro_subdivision(device):
    """A receiver plate between an occluder above and the ground below: with 3x3
    micro-subdivision no plate pixel is lit beyond the reference by more than 0.1; without it
    (subdivision = 1, values clamped) the incorrectly-lit penumbra appears (> 0.4, on over 10%
    of the plate)."""
    sc = wsoft.load_scene(essm_nonplanar())
    ref = wsoft.render(sc, "reference", width=128, height=128, samples=256, device=device)
    plate = (ref["A"] > 0) & (np.abs(ref["P.Z"] - 1.0) < 1e-3)
    assert plate.sum() > 4000
    on = wsoft.render(sc, "essm", width=128, height=128, device=device)
    off = wsoft.render(sc, "essm", width=128, height=128, device=device, subdivision=1)
    d_on = (on.V - ref.V)[plate]
    d_off = (off.V - ref.V)[plate]
    assert d_on.max() < 0.1
    assert d_off.max() > 0.4 and (d_off > 0.1).mean() > 0.1
    assert on.counters()["pcf_fallbacks"] > 0


def test_sat_tile_grid_stats_and_passes():
    """The stats report the tile grid chosen by the pyramid test and the pass count; the depth range
    comes from the min/max pyramid or the scene bounds."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "essm", width=64, height=48, shadow_map_size=512)
    c = f.counters()
    sat = c["sat"]
    assert sat["storage"] == "tiles" and sat["tile"] * sat["tiles_per_side"] == 512
    assert sat["passes"] == 2 * math.ceil(math.log(sat["tile"], 8) - 1e-9)
    assert any(t["passes"] for t in sat["levels_tested"])
    zr = c["z_range"]
    fb = wsoft.render(scene, "essm", width=64, height=48, shadow_map_size=512, depth_range="bounds")
    zb = fb.counters()["z_range"]
    assert zb[0] <= zr[0] + 1e-5 and zb[1] >= zr[1] - 1e-5
    assert any(p.startswith("essm_sat") for p in f.stats["passes"])
    assert {f.stats["pass_stages"][p] for p in f.stats["passes"] if p.startswith("essm")} == {"basis", "sat", "shadow"}


def test_anisotropic_levels_and_c_override_run():
    scene = wsoft.load_scene(scene_path("contact.usda"))
    for kw in ({"level": 1}, {"level": 3, "H": 2.0}, {"anisotropic": False}, {"c": 8.0}, {"mu": 24, "tile": 16}):
        f = wsoft.render(scene, "essm", width=64, height=48, shadow_map_size=512, **kw)
        assert np.isfinite(f.V).all() and 0.0 <= f.V.min() and f.V.max() <= 1.0


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"shadow_map_size": 1000}, "power of two"),
        ({"sat": "float16"}, "sat"),
        ({"build": "magic"}, "build"),
        ({"mu": 40}, "mu"),
        ({"tile": 48}, "tile"),
        ({"c": 200.0}, "c = 200 out of range"),
        ({"level": -1}, "level"),
        ({"subdivision": 0}, "subdivision"),
        ({"depth_range": "guess"}, "depth_range"),
        ({"colour": 1}, "no parameter"),
    ],
)
def test_essm_bad_parameters(bad, match):
    with pytest.raises(ParameterError, match=match):
        create("essm", bad)


def test_vssm_bad_parameters():
    with pytest.raises(ParameterError, match="bleed"):
        create("vssm", {"bleed": 1.0})
    with pytest.raises(ParameterError, match="power of two"):
        create("vssm", {"shadow_map_size": 300})


def test_cli_essm_bad_value(tmp_path):
    from wsoft.cli import main

    rc = main(["render", scene_path("box_plane.usda"), "-t", "essm", "--set", "sat=half", "--out", str(tmp_path / "x.exr")])
    assert rc == 2


def test_receiver_hidden_past_the_range_stays_in_shadow(tmp_path):
    """A closed room under a rect light (the ceiling the map's farthest caster, every receiver hidden
    past the effective range's far end): ``beyond_range=flat`` keeps them dark, where their tilted
    tangent planes (``plane``) reach back to the ceiling's depth and let light through."""
    from wsoft.stages.adversarial import b_room_ceiling

    path = b_room_ceiling(str(tmp_path))
    flat = wsoft.render(path, "essm", width=48, height=36, shadow_map_size=256)
    tilted = wsoft.render(path, "essm", width=48, height=36, shadow_map_size=256, beyond_range="plane")
    cov = flat["A"] > 0
    assert float(flat.V[cov].mean()) <= 0.01
    assert float(tilted.V[cov].mean()) > 0.03  # measured 0.068
    with pytest.raises(ParameterError, match="beyond_range"):
        create("essm", {"beyond_range": "clamp"})
