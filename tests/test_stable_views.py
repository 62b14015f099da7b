"""Stable light views (``view=stable``, :mod:`wsoft.lightspace.stable`): under a camera that turns
and moves a little, the texel size stays and the window moves by whole texels of a fixed grid,
where the fitted default's slides; they hold every receiver; a sequence's receivers fit one view
for all its frames; every shadow-map technique renders with one close to the reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import scene_path

import wsoft
from wsoft.lightspace.fit import fit_light_view
from wsoft.lightspace.stable import fit_stable_view, ladder_down, ladder_up, snapped_depths
from wsoft.params import LightViewParams
from wsoft.scene.types import Camera
from wsoft.techniques import TECHNIQUES

DOWN = np.array([0.0, 0.0, -1.0])  # the bundled stages are Z-up: a sphere light's stable view looks down
SIZE = 256  # light map texels per side
W, H = 64, 48
STABLE_MAE = 0.01  # box_plane at 64 x 48 against 16 reference samples: every technique's stable view is within it
STABLE_MAE_SLACK = 0.001  # box_plane: a stable view's MAE may exceed the fitted view's by this (3 of its 2884 ground pixels wrong)


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A camera's to-world matrix at ``eye`` looking at ``target`` (the camera looks down its −Z)."""
    eye = np.asarray(eye, np.float64)
    z = eye - np.asarray(target, np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, np.cross(z, x), z, eye
    return m


def receivers_of(frame) -> np.ndarray:
    """The world points a frame's covered pixels see, [N, 3]."""
    cov = frame["A"] > 0
    return np.stack([frame["P.X"][cov], frame["P.Y"][cov], frame["P.Z"][cov]], axis=1).astype(np.float64)


def fit_pass(frame) -> dict:
    """The counters of the frame's (one) stable light-view pass."""
    fits = {k: v for k, v in frame.stats["counters"]["passes"].items() if k.startswith("fit_light_view") and k.endswith("+stable")}
    assert len(fits) == 1, list(frame.stats["counters"]["passes"])
    return next(iter(fits.values()))


def texel_origin(view) -> tuple[float, float]:
    """Where the view's texel (0, 0) corner lies on its x and y axes, from the world origin."""
    l, _, b, _ = view.window
    o = np.asarray(view.origin, np.float64)
    return float(o @ view.axes[:, 0] + l), float(o @ view.axes[:, 1] + b)


def texel_size(view) -> tuple[float, float]:
    l, r, b, t = view.window
    return (r - l) / view.width, (t - b) / view.height


# the camera turns (and in the last frame also moves a little)
EYE = np.array([0.0, -12.0, 8.0])
TURN = [(EYE, (0.0, 0.0, 0.0)), (EYE, (1.0, 0.5, 0.0)), (EYE + (0.2, 0.1, 0.0), (1.0, 0.7, 0.0))]


def footprint_turn(lamp) -> list:
    """A smaller turn (and move) about a local light's footprint on the ground (z = 0), where its
    view holds what the camera sees (a local view's window is in tangents: the nearer the
    receivers, the more a turn changes it)."""
    foot = np.array([lamp.position[0], lamp.position[1], 0.0])
    eye = foot + 0.5 * EYE
    return [(eye, foot), (eye, foot + (0.15, 0.1, 0.0)), (eye + (0.05, 0.03, 0.0), foot + (0.2, 0.15, 0.0))]


def turning_frames(scene, light: str, device: str, turn=TURN):
    """``hard`` with a stable view under each camera of ``turn``."""
    return [wsoft.render(scene, "hard", width=W, height=H, device=device, camera=Camera(f"/c{i}", look_at(e, t)), light=light,
                         view="stable", cube="never", shadow_map_size=SIZE) for i, (e, t) in enumerate(turn)]


def test_ladder_and_depth_snapping():
    for x in (1e-9, 0.37, 1.0, 3.0, 1234.5):
        up, down = ladder_up(x), ladder_down(x)
        assert down <= x <= up < down * 2 ** 0.25 * (1 + 1e-12)
        assert math.isclose(math.log2(up) * 4, round(math.log2(up) * 4), abs_tol=1e-9)
    assert ladder_up(2.0) == 2.0 and ladder_up(2.0 * (1 + 1e-12)) > 2.0
    z0, z1, step = snapped_depths(-3.3, 7.1)
    assert z0 <= -3.3 and z1 >= 7.1 and math.isclose(z0 / step, round(z0 / step)) and math.isclose(z1 / step, round(z1 / step))
    assert snapped_depths(-3.25, 7.2) == (z0, z1, step)  # a slightly different range: the same snapped one


def test_distant_stable_view_keeps_its_texel_grid_under_a_turning_camera(device):
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    sun = next(l for l in scene.lights if l.name == "Sun")
    lo, hi = scene.bounds
    frames = turning_frames(scene, "Sun", device)
    recs = [receivers_of(f) for f in frames]
    stable = [fit_stable_view(sun, r, lo, hi, SIZE, casters=scene.caster_points) for r in recs]
    fitted = [fit_light_view(sun, r, lo, hi, SIZE, casters=scene.caster_points) for r in recs]
    # the fitted default slides: its texel size and grid change from frame to frame
    assert len({round(texel_size(v)[0], 9) for v in fitted}) == 3
    tx0 = texel_size(fitted[0])[0]
    assert any(abs(texel_origin(v)[0] - texel_origin(fitted[0])[0]) / tx0 % 1.0 > 0.05 for v in fitted[1:])
    # the stable view: one texel size; its window moves by whole texels; depth range kept
    tx = texel_size(stable[0])
    assert tx[0] == tx[1]
    assert len({tuple(v.snap["snap_offset"]) for v in stable}) > 1  # the window did move
    for v, f in zip(stable, frames):
        assert texel_size(v) == pytest.approx(tx, rel=1e-12)
        for k in range(2):
            n = texel_origin(v)[k] / tx[k]
            assert abs(n - round(n)) < 1e-6
        assert (v.near, v.far) == (stable[0].near, stable[0].far)
        assert np.allclose(v.origin @ v.axes[:, 2], stable[0].origin @ stable[0].axes[:, 2], rtol=0, atol=1e-12)
        c = fit_pass(f)  # the render's own pass fitted the same view and says so
        assert c["view"] == "stable" and c["texel"] == pytest.approx(tx[0], rel=1e-12) and c["snap_offset"] == v.snap["snap_offset"]
        assert c["radius"] == v.snap["radius"] and c["receivers_outside"] == 0
    # a receiver seen in every frame falls at the same place within its texel in each
    p = recs[0][::7]  # frame 0's receivers in the part of the ground every frame sees
    seen = p[np.all([np.linalg.norm(p[:, None] - r[None, ::3], axis=2).min(axis=1) < 0.3 for r in recs[1:]], axis=0)]
    assert len(seen) > 20
    frac = [np.stack(v.texel_coords(seen), axis=1) % 1.0 for v in stable]
    for fr in frac[1:]:
        d = np.abs(fr - frac[0])
        assert np.all(np.minimum(d, 1.0 - d) < 1e-5)
    ffrac = [np.stack(v.texel_coords(seen), axis=1) % 1.0 for v in fitted]
    assert np.max(np.abs(ffrac[1] - ffrac[0])) > 0.1  # where the fitted views put it differs


@pytest.mark.parametrize("file,light", [("box_plane.usda", "Light"), ("multi_light.usda", "Sphere"), ("multi_light.usda", "Rect")])
def test_local_stable_view_keeps_its_texel_grid_under_a_turning_camera(device, file, light):
    scene = wsoft.load_scene(scene_path(file))
    lamp = next(l for l in scene.lights if l.name == light)
    lo, hi = scene.bounds
    frames = turning_frames(scene, light, device, footprint_turn(lamp))
    recs = [receivers_of(f) for f in frames]
    stable = [fit_stable_view(lamp, r, lo, hi, SIZE, down=DOWN) for r in recs]
    fitted = [fit_light_view(lamp, r, lo, hi, SIZE) for r in recs]
    assert len({tuple(np.round(v.window, 9)) for v in fitted}) == 3  # the fitted windows change
    tx = texel_size(stable[0])
    for v, f, rec in zip(stable, frames, recs):
        assert texel_size(v) == pytest.approx(tx, rel=1e-12)
        assert np.array_equal(v.axes, stable[0].axes) and np.array_equal(v.origin, stable[0].origin)
        l, _, b, _ = v.window  # tangent windows: whole texels from the light's axis
        assert abs(l / tx[0] - round(l / tx[0])) < 1e-6 and abs(b / tx[1] - round(b / tx[1])) < 1e-6
        assert (v.near, v.far) == (stable[0].near, stable[0].far)
        c = fit_pass(f)
        assert c["view"] == "stable" and c["texel"] == pytest.approx(list(tx), rel=1e-12) and c["receivers_outside"] == 0
        x, y = v.texel_coords(rec)
        assert x.min() >= 0.5 and y.min() >= 0.5 and x.max() <= SIZE - 0.5 and y.max() <= SIZE - 0.5
    p = recs[0][::29]
    frac = [np.stack(v.texel_coords(p), axis=1) % 1.0 for v in stable]
    d = np.abs(frac[1] - frac[0])
    assert np.all(np.minimum(d, 1.0 - d) < 1e-5)


@pytest.mark.parametrize("file,light", [("box_plane.usda", "Light"), ("city.usdc", "Sun"), ("city.usdc", "Rect")])
def test_stable_views_hold_every_receiver(device, file, light):
    scene = wsoft.load_scene(scene_path(file))
    f = wsoft.render(scene, "pcss", width=W, height=H, device=device, light=light, view="stable", cube="never", shadow_map_size=SIZE)
    c = fit_pass(f)
    assert c["receivers_outside"] == 0
    lamp = next(l for l in scene.lights if l.name == light)
    rec = receivers_of(f)
    v = fit_stable_view(lamp, rec, *scene.bounds, SIZE, casters=scene.caster_points, down=DOWN)
    assert v.snap["snap_offset"] == c["snap_offset"]
    x, y = v.texel_coords(rec)
    assert len(x) == len(rec) and x.min() >= 0.5 and y.min() >= 0.5 and x.max() <= SIZE - 0.5 and y.max() <= SIZE - 0.5
    assert np.isfinite(f.V).all()


@pytest.mark.parametrize("light", ["Sun", "Sphere"])
def test_sequence_receivers_fit_one_view_for_every_frame(device, light):
    """``fit_receivers``: each frame's stable view is the sequence's, and holds all its receivers."""
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    lamp = next(l for l in scene.lights if l.name == light)
    lo, hi = scene.bounds
    turn = TURN if lamp.kind_name == "distant" else footprint_turn(lamp)
    frames = turning_frames(scene, light, device, turn)
    recs = [receivers_of(f) for f in frames]
    region = np.concatenate(recs)
    casters = scene.caster_points if lamp.kind_name == "distant" else None  # as the context fits a (hard) view
    views = [fit_stable_view(lamp, r, lo, hi, SIZE, casters=casters, region=region, down=DOWN) for r in recs]
    alone = fit_stable_view(lamp, recs[0], lo, hi, SIZE, casters=casters, down=DOWN)
    for v in views:
        assert v.window == views[0].window and np.array_equal(v.origin, views[0].origin) and (v.near, v.far) == (views[0].near, views[0].far)
        assert v.receivers_outside == 0
        x, y = v.texel_coords(region)
        assert len(x) == len(region) and x.min() >= 0.5 and y.min() >= 0.5 and x.max() <= SIZE - 0.5 and y.max() <= SIZE - 0.5
    assert views[0].snap != alone.snap  # the sequence's view is not the first frame's own

    # through the render context: a ring of ground points about the light's footprint, wider than any frame's view
    from wsoft.pipeline import build_graph, execute

    foot = np.array([lamp.position[0], lamp.position[1], 0.0]) if lamp.kind_name != "distant" else np.zeros(3)
    ring = foot + [[10.0 * math.cos(a), 10.0 * math.sin(a), 0.0] for a in np.linspace(0.0, 2.0 * math.pi, 24, endpoint=False)]
    built = build_graph(scene, "hard", width=W, height=H, device=device, light=light, camera=Camera("/c1", look_at(*turn[1])),
                        params={"view": "sequence", "cube": "never", "shadow_map_size": SIZE})
    built.ctx.fit_receivers = {lamp.path: ring}
    execute(built, device)
    c = built.ctx.counters["passes"][f"fit_light_view[{light}]@{SIZE}+sequence"]
    v = fit_stable_view(lamp, recs[1], lo, hi, SIZE, casters=casters, region=ring, down=DOWN)
    assert c["snap_offset"] == v.snap["snap_offset"] and c["radius"] == v.snap["radius"] and c["texel"] == v.snap["texel"]
    assert c["radius"] != fit_pass(frames[1])["radius"]  # the ring, not the frame's receivers, set its size
    x, y = v.texel_coords(ring)
    assert len(x) == len(ring) and x.min() >= 0.5 and y.min() >= 0.5 and x.max() <= SIZE - 0.5 and y.max() <= SIZE - 0.5


VIEW_TECHNIQUES = sorted(n for n, c in TECHNIQUES.items() if issubclass(c.Params, LightViewParams))


def test_every_shadow_map_technique_has_the_option():
    assert {"hard", "pcf", "pcss", "vsm", "esm", "evsm", "msm", "msm_soft", "essm", "vssm", "ssm", "salzman"} <= set(VIEW_TECHNIQUES)
    for name in VIEW_TECHNIQUES:
        assert TECHNIQUES[name].defaults()["view"] == "fitted"
        with pytest.raises(wsoft.ParameterError, match=r"^" + name + r": view 'wobbly' is not one of fitted, stable, sequence$"):
            TECHNIQUES[name].make_params({"view": "wobbly"})
    table = wsoft.techniques.markdown_table()
    assert table.count("`view` ('fitted')") == len([n for n in VIEW_TECHNIQUES if n in wsoft.techniques.bundled_names()])


def test_every_technique_renders_with_a_stable_view(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    techs = []
    for name in VIEW_TECHNIQUES:
        q = dict(TECHNIQUES[name].quick_params)
        techs += [(name, q), (name, {**q, "view": "stable"})]
    fs = wsoft.compare(scene, techs, samples=16, width=W, height=H, device=device)
    labels = [label for label in fs if fs[label].stats.get("error")]
    assert len(labels) == 2 * len(VIEW_TECHNIQUES)
    for fitted, stable in zip(labels[0::2], labels[1::2]):
        assert "view=stable" in stable and "view=stable" not in fitted
        f = fs[stable]
        assert any(p.startswith("fit_light_view[Light]") and p.endswith("+stable") for p in f.stats["passes"])
        assert np.isfinite(f.V).all()
        e, e0 = f.stats["error"]["mae"], fs[fitted].stats["error"]["mae"]
        assert e <= STABLE_MAE and e <= e0 + STABLE_MAE_SLACK, (stable, e, e0)


def test_stable_views_are_shared_and_distinct_from_fitted(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    fs = wsoft.render(scene, [("pcss", {"view": "stable", "shadow_map_size": SIZE}), ("vsm", {"view": "stable", "shadow_map_size": SIZE}),
                              ("pcss", {"shadow_map_size": SIZE})], width=W, height=H, device=device)
    passes = [p for p in fs.stats["passes"] if p.startswith("fit_light_view")]
    assert sorted(passes) == [f"fit_light_view[Light]@{SIZE}+soft", f"fit_light_view[Light]@{SIZE}+soft+stable"]
    assert len(fs.stats["shared_passes"][f"fit_light_view[Light]@{SIZE}+soft+stable"]) >= 1
