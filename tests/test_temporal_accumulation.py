"""rtdenoise's temporal accumulation over a sequence, one light view for a whole sequence
(``view=sequence``), and a stage whose geometry is not animated read once."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, UsdGeom

import wsoft
from wsoft.pipeline import History
from wsoft.metrics.sequences import compare_sequence
from wsoft.pipeline.sequence import render_sequence
from wsoft.scene.usd import open_stage, static_geometry
from wsoft.stages import add_box, add_camera, add_quad, add_rect_light, look_at_xform, make_stage

from conftest import scene_path


def _pan_stage(path: str, frames: int = 3):
    """A plate over the ground under a rect light, a camera sliding sideways (frames 1..frames)."""
    st = make_stage(path=path)
    st.SetStartTimeCode(1)
    st.SetEndTimeCode(frames)
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_box(st, "/World/Plate", (-0.6, -0.6, 1.0), (0.6, 0.6, 1.1))
    add_rect_light(st, "/World/Light", (0.3, 0.2, 3.0), 1.0, 1.0)
    cam = add_camera(st, "/World/Camera", (0, -5, 4), (0, 0, 0.3))
    op = UsdGeom.Xformable(cam.GetPrim()).GetOrderedXformOps()[0]
    for t in range(1, frames + 1):
        x = -0.8 + 0.4 * (t - 1)
        op.Set(look_at_xform((x, -5, 4), (x, 0, 0.3), (0, 0, 1)), t)
    st.GetRootLayer().Save()
    return path


@pytest.mark.slow
def test_accumulation_lowers_the_error_of_a_still_frame_and_says_so(tmp_path):
    from pxr import Usd

    still = Usd.Stage.CreateNew(str(tmp_path / "still.usda"))  # box_plane with a time range 1..6: nothing moves
    still.GetRootLayer().subLayerPaths.append(scene_path("box_plane.usda"))
    still.SetStartTimeCode(1)
    still.SetEndTimeCode(6)
    still.GetRootLayer().Save()
    seq = compare_sequence(str(tmp_path / "still.usda"), [("rtdenoise", {"samples": 1, "history": 8}), ("rtdenoise", {"samples": 1})],
                           frames=[1, 2, 3, 4, 5, 6], samples=64, width=64, height=48)
    acc = [fs["rtdenoise(samples=1,history=8)"].stats["error"]["mae_penumbra"] for fs in seq.frames]
    one = [fs["rtdenoise(samples=1)"].stats["error"]["mae_penumbra"] for fs in seq.frames]
    assert acc[0] == one[0]  # the first frame has no history
    assert np.mean(acc[3:]) < 0.8 * np.mean(one[3:])
    c0 = seq[0]["rtdenoise(samples=1,history=8)"].counters()
    c5 = seq[5]["rtdenoise(samples=1,history=8)"].counters()
    assert c0["history"] == "first frame" and c0["history_samples"] == 0
    assert c5["history"] == "reprojected" and c5["disoccluded"] < 0.02 * 64 * 48 and c5["history_mean_length"] > 5.5
    assert "history" not in seq[5]["rtdenoise(samples=1)"].counters()
    m = seq.summary["temporal"]
    assert m["rtdenoise(samples=1,history=8)"]["Light"]["temporal_std"] < m["rtdenoise(samples=1)"]["Light"]["temporal_std"]


def test_a_single_frame_has_no_history():
    f = wsoft.render(scene_path("box_plane.usda"), "rtdenoise", width=32, height=24)
    assert "history" not in f.counters()
    h = History()
    f0 = wsoft.render(scene_path("box_plane.usda"), ("rtdenoise", {"history": 8}), width=32, height=24, frame_history=h)
    assert f0.counters()["history"] == "first frame" and np.array_equal(f0.V, f.V)  # frame 0: the single frame's rays


def test_a_moving_camera_reprojects_and_disoccludes(tmp_path):
    p = _pan_stage(str(tmp_path / "pan.usda"))
    seq = render_sequence(p, ("rtdenoise", {"history": 8}), frames="1:3", width=64, height=48)
    c = seq[1].counters()
    assert c["history"] == "reprojected" and c["history_samples"] > 0.5 * 64 * 48 and c["disoccluded"] > 0
    assert np.isfinite(seq[2].V).all()


@pytest.mark.slow
def test_a_light_view_fitted_once_for_the_sequence(tmp_path):
    p = _pan_stage(str(tmp_path / "pan.usda"))
    techs = [("hard", {"shadow_map_size": 512, "view": v}) for v in ("stable", "sequence")]
    seq = render_sequence(p, techs, frames="1:3", width=48, height=36)
    wins = []
    for fs in seq.frames:
        label = next(l for l in fs if "view=sequence" in l)
        passes = fs[label].stats["counters"]["passes"]
        fit = next(v for k, v in passes.items() if k.startswith("fit_") and "+sequence" in k)
        assert fit["receivers_outside"] == 0
        wins.append(repr((fit["radius"], fit["snap_offset"], fit["texel"])))
    assert len(set(wins)) == 1  # one view for every frame
    one = wsoft.render(wsoft.load_scene(p, time=2), ("hard", {"shadow_map_size": 512, "view": "sequence"}), width=48, height=36)
    assert np.array_equal(one.V, wsoft.render(wsoft.load_scene(p, time=2), ("hard", {"shadow_map_size": 512, "view": "stable"}),
                                               width=48, height=36).V)  # a single frame: the stable view


def test_static_geometry_is_read_once_and_gives_the_same_frames(tmp_path):
    p = _pan_stage(str(tmp_path / "pan.usda"))
    assert static_geometry(open_stage(p))
    assert not static_geometry(open_stage(scene_path("lightmapped_bridge.usda")))
    seq = render_sequence(p, ["pcss", ("reference", {"samples": 4})], frames="1:3", width=48, height=36, reseed=False)
    assert [s["scene"] for s in seq.stats] == ["built", "reused", "reused"]
    assert all(s.get("geometry", "").startswith("static") for s in seq.stats[1:])
    for t, fs in zip(seq.times, seq.frames):
        fresh = wsoft.render(wsoft.load_scene(p, time=t), ["pcss", ("reference", {"samples": 4})], width=48, height=36)
        for label in fs:
            assert np.array_equal(fs[label].V, fresh[label].V)
        assert fs["pcss"].stats["camera_model"] == fresh["pcss"].stats["camera_model"]


def test_a_moving_mesh_under_a_still_parent_is_not_static(tmp_path):
    st = make_stage(path=str(tmp_path / "m.usda"))
    st.SetStartTimeCode(1)
    st.SetEndTimeCode(2)
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    box = add_box(st, "/World/Box", (-0.5, -0.5, 1.0), (0.5, 0.5, 1.5))
    op = UsdGeom.Xformable(box.GetPrim()).AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 1)
    op.Set(Gf.Vec3d(1, 0, 0), 2)
    add_rect_light(st, "/World/Light", (0, 0, 3), 1, 1)
    st.GetRootLayer().Save()
    assert not static_geometry(open_stage(str(tmp_path / "m.usda")))
