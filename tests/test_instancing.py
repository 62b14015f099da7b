"""Instances kept instanced on the device (wsoft.scene.instancing): eye rays, shadow rays and light
maps of an instanced scene against the same scene flattened in numpy (tests/instancing_util.py)."""

from __future__ import annotations

import os

import numpy as np
import pytest
import warp as wp

from conftest import SKY_ONLY
from instancing_util import rot, split, xf
from wsoft.errors import ParameterError
from wsoft.pipeline import build_graph, render
from wsoft.scene.usd import load_scene
from wsoft.techniques import TECHNIQUES

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CUTOUT = os.path.join(ROOT, "usd_scenes", "cutout.usda")
# the techniques that read light depth maps and keep a stage's instances
MAP_TECHNIQUES_KEEPING_INSTANCES = [n for n, c in sorted(TECHNIQUES.items()) if not c.instancing_refusal and "light_depth" in c.reads()
                                    and n not in SKY_ONLY]  # the sky's own maps: tests/test_skymaps.py

# the fence (a cutout quad) and the leaf box (closed, single-sided) become prototypes; instances:
# identity, rotated + anisotropically scaled, translated, rotated + mirrored (negative x scale)
PLACEMENTS = [(0, xf()), (0, xf(rot((0, 0, 1), 0.5), (0.6, 0.3, 0.4), (0.7, 0.7, 1))), (1, xf(t=(-0.8, 0.5, 0.3))),
              (1, xf(rot((1, 0, 0), 0.3), (0.9, -0.7, 0.6), (-1, 1, 1)))]


@pytest.fixture(scope="module")
def pair():
    inst, flat = split(load_scene(CUTOUT), ["Fence", "Leaf"], PLACEMENTS)
    inst.__dict__["flattened"] = lambda: flat  # what the loader's Scene.flattened() gives for a stage
    return inst, flat


def gbuffer_of(scene, device, w=96, h=72):
    from wsoft.raster.camera import camera_gpu
    from wsoft.raster.gbuffer import render_gbuffer
    from wsoft.pipeline import frame_setup
    from wsoft.scene.device import upload_scene

    cam = camera_gpu(frame_setup(scene, w, h).camera)
    ds = upload_scene(scene, device)
    return ds, render_gbuffer(ds, cam, w, h, 1, True)


def test_split_is_what_it_claims(pair):
    inst, flat = pair
    assert inst.instanced and inst.instances.count == 4 and inst.triangle_count == 2  # the ground stays in the soup
    assert inst.total_triangles == flat.triangle_count
    assert inst.has_cutouts and inst.cutout_triangle_counts() == flat.cutout_triangle_counts()
    np.testing.assert_allclose(inst.bounds[0], flat.bounds[0], atol=1e-5)
    np.testing.assert_allclose(inst.bounds[1], flat.bounds[1], atol=1e-5)
    assert np.array_equal(np.sort(inst.caster_points, axis=0), np.sort(flat.caster_points, axis=0))


def test_eye_rays_meet_instances_as_the_flat_scene(pair, device):
    """Same hits, points within float rounding (the instanced ray is carried into the prototype's
    frame), same normals, the same triangle's albedo; a mirrored single-sided box culls the same faces."""
    inst, flat = pair
    dsa, a = gbuffer_of(inst, device)
    dsb, b = gbuffer_of(flat, device)
    ha, hb = a.prim.numpy() >= 0, b.prim.numpy() >= 0
    assert np.array_equal(ha, hb) and ha.sum() > 1000
    pa, pb = a.pos.numpy()[ha], b.pos.numpy()[hb]
    assert np.abs(pa - pb).max() < 1e-5
    assert np.abs(a.nrm.numpy()[ha] - b.nrm.numpy()[hb]).max() < 1e-4
    # some samples lie on instances (combined indices past the soup's triangles)
    on_inst = a.prim.numpy()[ha] >= inst.triangle_count
    assert on_inst.sum() > 300
    assert np.allclose(dsa.tri_albedo.numpy()[a.prim.numpy()[ha]], dsb.tri_albedo.numpy()[b.prim.numpy()[hb]])


def test_reference_equals_flat_bit_for_bit(pair, device):
    inst, flat = pair
    a = render(inst, "reference", width=96, height=72, samples=64, traversal="ray", device=device)
    b = render(flat, "reference", width=96, height=72, samples=64, traversal="ray", device=device)
    assert np.array_equal(a.V, b.V)
    assert 0.05 < (a.V < 0.99).mean() < 0.9  # shadows and penumbrae from the instances
    assert a.stats["scene"]["instancing"]["mode"] == "kept"
    # auto traversal: rays go one by one through the top level (packets walk the soup only)
    c = render(inst, "reference", width=96, height=72, samples=64, device=device)
    assert np.array_equal(c.V, a.V)
    with pytest.raises(ParameterError, match="traversal=packet does not reach instances"):
        render(inst, "reference", width=32, height=24, samples=16, traversal="packet", device=device)


@pytest.mark.parametrize("tech", MAP_TECHNIQUES_KEEPING_INSTANCES)
def test_map_techniques_keep_instances(pair, tech):
    """The maps draw the instances; the image equals the flat scene's but for pixels whose eye
    point moved by float rounding on a borderline (self-shadowed) surface."""
    inst, flat = pair
    a = render(inst, tech, width=96, height=72, shadow_map_size=512)
    b = render(flat, tech, width=96, height=72, shadow_map_size=512)
    d = np.abs(a.V - b.V)
    assert a.stats["scene"]["instancing"]["mode"] == "kept"
    assert d.mean() < 5e-3 and (d > 0.01).mean() < 0.02, (d.mean(), (d > 0.01).mean())
    assert (a.V < 0.5).mean() > 0.02  # something is shadowed


def test_depth_map_of_instances_equals_flat_map(device):
    """Translated instances (their float32 vertices equal the flattened ones exactly): the instanced
    map equals the flat map texel for texel, plain and conservative. Mirrored ones: the same texels
    written, depths within float rounding (a mirrored closed box's far faces are culled as the flat
    scene's are; culling the wrong side would move depths by the box's thickness)."""
    from wsoft.lightspace.fit import fit_light_view
    from wsoft.raster.depth_map import rasterize

    from wsoft.lightspace.view import DEPTH_CLEAR

    for sx in (1, -1):
        T = [(1, xf(t=(dx, dy, 0.25), s=(sx, 1, 1))) for dx in (-1.5, -0.5, 0.5, 1.5) for dy in (-1.0, 0.0, 1.0)] + [(0, xf(t=(0.25, 0.5, 0.5)))]
        inst, flat = split(load_scene(CUTOUT), ["Fence", "Leaf"], T)
        dsa, ga = gbuffer_of(inst, device)
        dsb, gb = gbuffer_of(flat, device)
        rec = gb.pos.numpy()[gb.prim.numpy() >= 0]
        v = fit_light_view(flat.lights[0], rec, *flat.bounds, 512)
        for conservative in (False, True):
            ma = rasterize(dsa, v, True, conservative=conservative)
            mb = rasterize(dsb, v, True, conservative=conservative)
            a, b = ma.depth.numpy(), mb.depth.numpy()
            assert ma.instances_drawn == len(T)
            if sx == 1:
                assert np.array_equal(a, b)
            else:  # the flattened mirrored mesh's winding is flipped: the same texels, depths interpolated in another corner order
                assert np.array_equal(a == DEPTH_CLEAR, b == DEPTH_CLEAR)
                w = b != DEPTH_CLEAR
                assert np.abs(a[w] - b[w]).max() <= 1e-6 * np.abs(b[w]).max()


def test_instances_outside_the_view_are_skipped_not_lost(device):
    """boxes_in_view drops only instances that cannot reach the map: the map is the same as when
    every instance is drawn, and far-away instances are skipped."""
    from wsoft.lightspace.fit import fit_light_view
    from wsoft.lightspace.view import boxes_in_view
    from wsoft.raster import depth_map as D

    T = [(1, xf(t=(dx, dy, 0.2))) for dx in np.linspace(-3, 3, 5) for dy in np.linspace(-3, 3, 5)] + [(1, xf(t=(400, 0, 0)))]
    inst, flat = split(load_scene(CUTOUT), ["Fence", "Leaf"], T)
    dsa, ga = gbuffer_of(inst, device)
    rec = ga.pos.numpy()[ga.prim.numpy() >= 0]
    v = fit_light_view(inst.lights[0], rec, *inst.bounds, 256)
    seen, inside = boxes_in_view(v, dsa.instances.lo, dsa.instances.hi)
    assert not seen[-1] and seen.sum() >= 9 and not inside.any()
    culled = D.rasterize(dsa, v, False).depth.numpy()
    orig = D.boxes_in_view
    try:
        D.boxes_in_view = lambda view, lo, hi: (np.ones(len(lo), bool), np.zeros(len(lo), bool))
        every = D.rasterize(dsa, v, False).depth.numpy()
    finally:
        D.boxes_in_view = orig
    assert np.array_equal(culled, every)


def test_all_instanced_scene_has_no_stray_soup_triangle(device):
    """A stage whose every mesh is instanced keeps a zero-area stand-in soup triangle: no ray hits
    it and no map, not even a conservative one, draws it."""
    from wsoft.lightspace.fit import fit_light_view
    from wsoft.raster.depth_map import rasterize
    from wsoft.scene.device import upload_scene

    sc = load_scene(CUTOUT)
    inst, flat = split(sc, ["Ground", "Fence", "Leaf"], [(0, xf()), (1, xf()), (2, xf())])
    assert inst.triangle_count == 0 and inst.total_triangles == flat.triangle_count
    a = render(inst, "reference", width=64, height=48, samples=16, device=device)
    b = render(flat, "reference", width=64, height=48, samples=16, device=device)
    assert np.array_equal(a.V, b.V)
    ds = upload_scene(inst, device)
    rec = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    v = fit_light_view(inst.lights[0], rec, *inst.bounds, 256)
    # the stand-in sits at the origin, inside the view: only the instances may write
    only_soup = rasterize(ds, v, False, conservative=True)
    ds.instances.lo[:] = 1e9  # every instance out of view: the map must stay empty
    ds.instances.hi[:] = 1e9 + 1
    empty = rasterize(ds, v, False, conservative=True).depth.numpy()
    from wsoft.lightspace.view import DEPTH_CLEAR

    assert np.all(empty == DEPTH_CLEAR)
    assert np.any(only_soup.depth.numpy() != DEPTH_CLEAR)


def test_instanced_rasterizer_on_many_threads(monkeypatch):
    """Small CPU chunks (many private maps) give the same instanced map as one chunk."""
    from wsoft.lightspace.fit import fit_light_view
    from wsoft.raster import rasterizer as R
    from wsoft.raster.depth_map import rasterize

    T = [(1, xf(rot((0, 0, 1), 0.1 * k), (np.cos(k) * 2, np.sin(k) * 2, 0.3))) for k in range(40)]
    inst, flat = split(load_scene(CUTOUT), ["Fence", "Leaf"], T)
    ds, gb = gbuffer_of(inst, "cpu")
    rec = gb.pos.numpy()[gb.prim.numpy() >= 0]
    v = fit_light_view(inst.lights[0], rec, *inst.bounds, 256)
    one = rasterize(ds, v, False).depth.numpy()
    monkeypatch.setattr(R, "CPU_CHUNK", 7)
    monkeypatch.setattr(R, "BIG_TRIANGLE_TEXELS", 64)
    many = rasterize(ds, v, False).depth.numpy()
    assert np.array_equal(one, many)


def test_techniques_that_read_the_soup_get_it_flattened(pair):
    inst, flat = pair
    for tech in ("izb", "salzman"):
        built = build_graph(inst, tech, width=32, height=24)
        assert built.instancing["mode"] == "flattened" and built.ctx.scene is flat
    a = render(inst, ["izb", "hard"], width=48, height=36)
    assert a.stats["scene"]["instancing"]["mode"] == "flattened"
    assert built.instancing["needs"][0][0] == "salzman"


def test_flattening_a_huge_instanced_stage_is_refused(pair, monkeypatch):
    from wsoft.pipeline import loading

    inst, _ = pair
    monkeypatch.setattr(loading, "FLATTEN_LIMIT", 10)
    with pytest.raises(ParameterError, match=r"izb \(its light pass.*needs the stage flattened.*techniques that keep instances: .*hard"):
        build_graph(inst, "izb", width=32, height=24)
    build_graph(inst, "hard", width=32, height=24)  # keeps instances: no limit


def test_plan_says_what_keeps_instances(pair, monkeypatch):
    from wsoft.pipeline import loading, plan

    inst, _ = pair
    p = plan(inst, ["hard", "izb"], width=32, height=24)
    assert p["instancing"]["mode"] == "kept" and p["instancing"]["instances"] == 4
    assert "izb" in p["flattened_for"] and "hard" not in p.get("flattened_for", {}) and "izb" in p["techniques"]
    monkeypatch.setattr(loading, "FLATTEN_LIMIT", 10)
    p = plan(inst, ["hard", "izb"], width=32, height=24)
    assert "izb" not in p["techniques"] and "needs the stage flattened" in p["not_applicable"]["izb"][0]["reason"]


def test_cli_instancing_flag(tmp_path):
    """--instancing keep renders city with its instances kept; flatten and auto give one soup."""
    import json

    from conftest import wsoft_cli

    stats = {}
    for mode in ("keep", "flatten", "auto"):
        out = tmp_path / f"{mode}.json"
        r = wsoft_cli("render", "city", "-t", "hard", "--width", "48", "--height", "36", "--set", "shadow_map_size=256", "--instancing", mode,
                      "--out", str(tmp_path / f"{mode}.exr"), "--stats", str(out))
        assert r.returncode == 0, r.stderr
        stats[mode] = json.loads(out.read_text())
    assert stats["keep"]["scene"]["instancing"]["mode"] == "kept" and stats["keep"]["scene"]["instancing"]["instances"] == 344
    assert stats["flatten"]["scene"]["instancing"]["mode"] == "none" and stats["auto"]["scene"]["instancing"]["mode"] == "none"
    assert stats["keep"]["scene"]["triangles"] == stats["flatten"]["scene"]["triangles"] == 1_041_866
    r = wsoft_cli("render", "city", "-t", "hard", "--instancing", "sometimes", "--out", str(tmp_path / "x.exr"))
    assert r.returncode == 2 and "--instancing" in r.stderr


@pytest.mark.parametrize("mirror", [1, -1])
def test_light_inside_an_instanced_closed_box(mirror):
    """A closed single-sided box placed around the light by an instance (mirrored or not): every
    map must keep the box's faces (culling its far side would lose them all and light the ground, a
    silent wrong answer); the ground is in shadow as in the flat scene and the reference."""
    sc = load_scene(CUTOUT)
    centre = np.array([2.5, 0.0, 0.9])  # the Leaf box's centre (1 x 1 x 0.6)
    M = xf(t=(0, 0, 4)) @ xf(s=(2.0 * mirror, 2.0, 3.0)) @ xf(t=-centre)
    inst, flat = split(sc, ["Fence", "Leaf"], [(1, M)])
    assert inst.instances.count == 1
    for tech in ("hard", "pcss", "reference"):
        kw = TECHNIQUES[tech].quick_params
        a = render(inst, tech, width=48, height=36, **kw)
        b = render(flat, tech, width=48, height=36, **kw)
        covered = a["A"] > 0 if "A" in a.channels else np.ones_like(a.V, bool)
        assert a.V[covered].max() < 0.05, (tech, a.V[covered].max())
        assert np.abs(a.V - b.V).mean() < 1e-3, tech
