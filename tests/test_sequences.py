"""Sequences (a stage at a run of time codes) and the temporal measures: flicker against the
reference, reprojection through the camera's motion, a stochastic technique's crawl."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from pxr import Gf, UsdGeom

import wsoft
from wsoft.metrics import GroundTruth, compare
from wsoft.metrics.temporal import SAME_POINT, FrameCamera, flicker, pair_pixels, positions, temporal_std
from wsoft.metrics.sequences import compare_sequence, temporal_measures
from wsoft.pipeline.sequence import Sequence, render_sequence
from wsoft.stages import add_box, add_camera, add_point_light, add_quad, add_rect_light, look_at_xform, make_stage

from conftest import scene_path, wsoft_cli

W, H = 48, 36


def _timed(stage, first: float = 1, last: float = 4):
    stage.SetStartTimeCode(first)
    stage.SetEndTimeCode(last)
    stage.SetTimeCodesPerSecond(24)
    return stage


def _still_box_plane(folder) -> str:
    """``box_plane.usda`` (nothing animated, no time range) under a root layer that authors the time
    range 1..4: a still stage a sequence may render."""
    from pxr import Usd

    st = Usd.Stage.CreateNew(os.path.join(str(folder), "still_box_plane.usda"))
    st.GetRootLayer().subLayerPaths.append(scene_path("box_plane.usda"))
    _timed(st)
    st.GetRootLayer().Save()
    return st.GetRootLayer().realPath


def _moving_light_stage(path: str, kind: str = "point"):
    """A plate over the ground under a light sliding 0.4 along x per frame (frames 1-4), camera still."""
    st = _timed(make_stage(path=path))
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    add_box(st, "/World/Plate", (-0.6, -0.6, 1.0), (0.6, 0.6, 1.1))
    light = add_point_light(st, "/World/Light", (0, 0, 3)) if kind == "point" else add_rect_light(st, "/World/Light", (0, 0, 3), 0.6, 0.6)
    op = UsdGeom.Xformable(light.GetPrim()).GetOrderedXformOps()[0]
    for i, t in enumerate((1, 2, 3, 4)):
        op.Set(Gf.Vec3d(-0.6 + 0.4 * i, 0.0, 3.0), t)
    add_camera(st, "/World/Camera", (0, -5, 5), (0, 0, 0.3))
    st.GetRootLayer().Save()
    return path


def _moving_camera_stage(path: str):
    """A box standing on the ground, still, seen by a camera sliding sideways (frames 1-3): ground
    hidden behind the box in one frame is seen in the next."""
    st = _timed(make_stage(path=path), 1, 3)
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_box(st, "/World/Box", (-0.5, -0.5, 0.0), (0.5, 0.5, 1.5))
    add_rect_light(st, "/World/Light", (1.0, 0.5, 4.0), 0.8, 0.8)
    cam = add_camera(st, "/World/Camera", (0, -5, 2.5), (0, 0, 0.5))
    op = UsdGeom.Xformable(cam.GetPrim()).GetOrderedXformOps()[0]
    for i, t in enumerate((1, 2, 3)):
        op.Set(look_at_xform((-0.6 + 0.6 * i, -5, 2.5), (-0.6 + 0.6 * i, 0, 0.5), (0, 0, 1)), t)
    st.GetRootLayer().Save()
    return path


def test_an_exact_technique_under_a_moving_light_has_zero_flicker(tmp_path):
    """A point light: one light sample is the exact answer, so the reference at 1 sample equals the
    ground truth in every frame while the shadow moves (reference change > 0): flicker exactly 0."""
    p = _moving_light_stage(str(tmp_path / "slide.usda"))
    seq = compare_sequence(p, [("reference", {"samples": 1})], frames="1:4", samples=4, width=W, height=H)
    m = seq.summary["temporal"]["reference"]["Light"]
    assert m["reference_change"] > 0.01  # the shadow moved
    assert m["flicker"] == 0.0 and m["mae"] == 0.0
    assert m["pairs"] == 3 and m["paired_pixels"] > 0.9 * 3 * W * H * 0.5


def test_a_jittered_map_is_measured_as_flickering(tmp_path):
    """The same still frame with the shadow map's texel grid moved between frames (other map sizes):
    the reference does not change, hard's edges do, and flicker says so; the same map every frame
    gives 0."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    gt = _truth(scene, 16)
    frames, truths = [], []
    for size in (256, 263, 256, 270):
        frames.append(compare(scene, [("hard", {"shadow_map_size": size})], ground_truth=gt, width=64, height=48))
        truths.append(gt)
    seq = Sequence(times=[1.0, 2.0, 3.0, 4.0], frames=frames)
    jittered = temporal_measures(seq, truths, static=True)["hard"]["Light"]
    steady = temporal_measures(Sequence(times=[1.0, 2.0], frames=[frames[0], frames[2]]), truths[:2], static=True)["hard"]["Light"]
    assert jittered["reference_change"] == 0.0
    moved = np.count_nonzero(frames[0]["hard"].V != frames[1]["hard"].V)
    assert moved > 0 and jittered["flicker"] > 1e-4
    assert jittered["flicker"] == pytest.approx(jittered["change"])
    assert jittered["temporal_std"] > 0.0
    assert steady["flicker"] == 0.0 and steady["temporal_std"] == 0.0


def _truth(scene, samples: int) -> GroundTruth:
    from wsoft.metrics.sequences import ground_truth_frame

    gt, _ = ground_truth_frame(scene, samples, width=64, height=48, camera=None, light=None, device=None)
    return gt


@pytest.mark.slow
def test_reprojection_keeps_only_surfaces_seen_in_both_frames(tmp_path):
    p = _moving_camera_stage(str(tmp_path / "pan.usda"))
    seq = render_sequence(p, "hard", frames="1:2", width=64, height=48, shadow_map_size=512)
    a, b = seq[0], seq[1]
    ca, cb = FrameCamera.of(a.stats), FrameCamera.of(b.stats)
    assert not ca.same_view(cb)
    pairs = pair_pixels(a.channels, b.channels, ca, cb)
    loose = pair_pixels(a.channels, b.channels, ca, cb, same_point=2.0)
    assert pairs.reprojected and pairs.disoccluded > 0 and len(pairs.cur) > 0.4 * pairs.covered
    assert len(loose.cur) > 0.8 * loose.covered and set(pairs.cur) <= set(loose.cur)
    pa, pb = positions(a.channels).reshape(-1, 3), positions(b.channels).reshape(-1, 3)
    foot = np.maximum(ca.footprint(pb[pairs.cur]), cb.footprint(pb[pairs.cur]))
    assert np.all(np.linalg.norm(pa[pairs.prev] - pb[pairs.cur], axis=1) <= SAME_POINT * foot + 1e-6)
    # a pixel of frame 2 on the ground whose point frame 1 saw hidden behind the box (well above its foot) is left out
    fx, fy, ok = ca.project(pb)
    col, row = np.clip(np.floor(fx).astype(int), 0, 63), np.clip(np.floor(fy).astype(int), 0, 47)
    seen_then = pa[row * 64 + col]
    hidden = ok & (np.asarray(b["A"]).reshape(-1) > 0) & (np.abs(pb[:, 2]) < 1e-4) & (seen_then[:, 2] > 0.2)
    assert hidden.sum() > 5  # the box hid ground that frame 2 sees
    assert not np.isin(np.flatnonzero(hidden), loose.cur).any()


def test_a_still_camera_pairs_the_same_pixels():
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "hard", width=32, height=24)
    c = FrameCamera.of(f.stats)
    pairs = pair_pixels(f.channels, f.channels, c, c)
    assert not pairs.reprojected and np.array_equal(pairs.cur, pairs.prev) and pairs.disoccluded == 0
    # projecting the frame's own points lands in their own pixels
    fx, fy, ok = c.project(positions(f.channels).reshape(-1, 3))
    cov = np.asarray(f["A"]).reshape(-1) > 0
    idx = np.floor(fy).astype(int) * 32 + np.floor(fx).astype(int)
    assert ok[cov].all() and np.mean(idx[cov] == np.flatnonzero(cov)) > 0.99


def test_flicker_arithmetic():
    r0, r1 = np.zeros((2, 2)), np.array([[0.0, 0.5], [1.0, 0.0]])
    pairs = pair_pixels({"A": np.ones((2, 2))}, {"A": np.ones((2, 2))}, *[FrameCamera(tuple(map(tuple, np.eye(4))), (1.0, 1.0), (0.0, 0.0),
                                                                                       False, 2, 2, (0, 0, 2, 2))] * 2)
    biased = flicker(r0 + 0.2, r1 + 0.2, r0, r1, pairs)  # a constant error does not flicker
    assert biased["flicker"] == pytest.approx(0.0) and biased["change"] == pytest.approx(0.375)
    frozen = flicker(r0, r0, r0, r1, pairs)  # a shadow that does not follow the reference
    assert frozen["flicker"] == pytest.approx(0.375) and frozen["change"] == 0.0
    nan = flicker(r0, np.full((2, 2), np.nan), r0, r0, pairs)
    assert nan["nonfinite"] == 4 and nan["flicker"] == 1.0
    assert temporal_std([r0, r1], np.ones((2, 2), bool)) == pytest.approx(np.std(np.stack([r0, r1]), axis=0, ddof=1).mean())


def test_a_still_stage_with_a_time_range_renders_the_same_frames_and_says_so(tmp_path):
    p = _still_box_plane(tmp_path)
    seq = render_sequence(p, ["hard", ("reference", {"samples": 4})], frames=[1, 2, 3], width=32, height=24)
    assert any("nothing on the stage varies over time" in w and "3 frames" in w for w in seq.warnings)
    assert [s["scene"] for s in seq.stats] == ["built", "reused", "reused"]
    for fs in seq.frames[1:]:
        assert np.array_equal(fs["hard"].V, seq[0]["hard"].V)
    assert not np.array_equal(seq[1]["reference"].V, seq[0]["reference"].V)  # other light samples per frame
    still = render_sequence(p, ("reference", {"samples": 4}), frames="1:2", width=32, height=24, reseed=False)
    assert np.array_equal(still[0].V, still[1].V)


@pytest.mark.slow
def test_the_reference_crawls_by_its_standard_error_on_a_static_sequence(tmp_path):
    """On a still stage the reference at N samples with new samples each frame changes only by its
    noise: its flicker against a fixed-seed ground truth and its temporal std match what its own
    standard errors predict, and shrink with more samples."""
    out, p = {}, _still_box_plane(tmp_path)
    for n in (4, 64):
        seq = compare_sequence(p, [("reference", {"samples": n})], frames="1:4", samples=64, width=48, height=36)
        m = seq.summary["temporal"]["reference"]["Light"]
        se = np.mean([np.mean(fs["reference"]["V_stderr"][fs["reference"]["A"] > 0]) for fs in seq.frames])
        out[n] = (m, se)
        assert 0.0 < m["temporal_std"] <= 1.5 * se
        assert m["reference_temporal_std"] == 0.0  # the ground truth keeps its seed
    assert out[64][0]["flicker"] < 0.5 * out[4][0]["flicker"]


@pytest.mark.slow
def test_moving_points_are_refitted_and_give_the_fresh_render():
    p = scene_path("lightmapped_bridge.usda")
    seq = render_sequence(p, ["hard", ("reference", {"samples": 4})], frames="1:3", width=48, height=36, light="Sun", reseed=False)
    assert [s["scene"] for s in seq.stats] == ["built", "refit", "refit"]
    for t, fs in zip(seq.times, seq.frames):
        fresh = wsoft.render(wsoft.load_scene(p, time=t), ["hard", ("reference", {"samples": 4})], width=48, height=36, light="Sun")
        for label in fs:
            assert np.array_equal(fs[label].V, fresh[label].V)
    assert not np.array_equal(seq[0]["hard"].V, seq[2]["hard"].V)  # the character walked


@pytest.mark.parametrize("frames, needle", [("0:3", "outside the stage's time range"), ("3:1", "before the first"),
                                            ("1:3:0", "step must be > 0"), ("1:x", "not a:b")])
def test_bad_frames_are_one_line_errors(tmp_path, frames, needle):
    p = _moving_light_stage(str(tmp_path / "slide.usda"))
    for cmd in (["render", p, "-t", "hard", "--out", str(tmp_path / "o.exr")], ["compare", p, "-t", "hard", "--out-dir", str(tmp_path)]):
        r = wsoft_cli(*cmd, "--frames", frames)
        assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_frames_and_time_together_are_refused(tmp_path):
    p = _moving_light_stage(str(tmp_path / "slide.usda"))
    r = wsoft_cli("render", p, "-t", "hard", "--frames", "1:2", "--time", "1", "--out", str(tmp_path / "o.exr"))
    assert r.returncode == 2 and "give one of them" in r.stderr


def test_cli_render_and_compare_write_numbered_frames(tmp_path):
    p = _moving_light_stage(str(tmp_path / "slide.usda"), kind="rect")
    r = wsoft_cli("render", p, "-t", "pcss", "--frames", "2:4", "--width", 32, "--height", 24, "--out", tmp_path / "o" / "v.exr",
                  "--png", tmp_path / "o" / "v.png", "--stats", tmp_path / "o" / "v.json")
    assert r.returncode == 0, r.stderr
    names = sorted(os.listdir(tmp_path / "o"))
    assert names == sorted([f"v.{n:04d}.{e}" for n in (2, 3, 4) for e in ("exr", "png", "json")] + ["v.json"])
    summary = json.loads((tmp_path / "o" / "v.json").read_text())
    assert summary["times"] == [2.0, 3.0, 4.0] and summary["summary"]["frames"] == 3
    assert [f["scene"] for f in summary["frames"]] == ["built", "reused", "reused"]  # only the light moves
    assert json.loads((tmp_path / "o" / "v.0003.json").read_text())["scene"]["time"] == 3.0
    r = wsoft_cli("compare", p, "-t", "hard", "-t", "pcss", "--frames", "1:3", "--width", 32, "--height", 24, "--samples", 16,
                  "--out-dir", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    md = (tmp_path / "c" / "slide-compare.md").read_text()
    assert "| hard | Light |" in md and "flicker" in md and "| 3 |" in md
    assert "![the first frame beside the reference](slide-compare.png)" in md and (tmp_path / "c" / "slide-compare.png").is_file()
    seq = json.loads((tmp_path / "c" / "slide-sequence.json").read_text())
    assert set(seq["summary"]["temporal"]) == {"hard", "pcss"}
    assert (tmp_path / "c" / "slide-pcss.0002.exr").is_file()
