"""How a sequence follows a stage's time: values USD says may vary (splines, time samples, value
clips, points moved by velocity) animate the frames; the stage's time range (authored, else the
span of its time samples and spline knots) bounds ``frames``; geometry below an animated light
moves with it, instances included."""

from __future__ import annotations

import numpy as np
import pytest

import wsoft
from wsoft.errors import ParameterError
from wsoft.pipeline.sequence import render_sequence, stage_is_animated
from wsoft.scene.usd import open_stage, static_geometry
from wsoft.scene.usd_context import earliest_time_sample
from wsoft.stages.builders import add_camera, add_class_root, add_instance, add_quad, add_rect_light, make_stage

from conftest import scene_path

W, H = 80, 60


def _base(path: str | None = None):
    """Ground ±6 at z = 0, a 1 x 1 occluder at z = 1, a 0.5 x 0.5 rect light at (3, 0, 3) facing
    down, a camera looking straight down from z = 12."""
    st = make_stage(path=path)
    add_quad(st, "/World/Ground", (0, 0, 0), 6)
    add_quad(st, "/World/Occluder", (0, 0, 1), 0.5)
    add_rect_light(st, "/World/Light", (3, 0, 3), 0.5, 0.5)
    add_camera(st, "/World/Cam", (0, 0, 12), (0, 0, 0), up=(0, 1, 0))
    return st


def _save(st) -> str:
    """Save ``st`` (usd-core's writer warns about splines' deprecated inner loops: kept off stderr)."""
    from pxr import UsdUtils

    d = UsdUtils.CoalescingDiagnosticDelegate()
    st.GetRootLayer().Save()
    d.TakeUncoalescedDiagnostics()
    return st.GetRootLayer().realPath


def _spline(attr, knots) -> None:
    """A linear spline through ``knots`` ((time, value), ...), held before the first and after the last."""
    from pxr import Ts

    sp = Ts.Spline("double")
    for t, v in knots:
        sp.SetKnot(Ts.Knot(typeName="double", time=float(t), value=float(v), nextInterp=Ts.InterpLinear))
    attr.SetSpline(sp)


def _occluder_at_y(tmp_path, y: float) -> str:
    """The base with the occluder moved by ``y`` along Y, nothing animated."""
    from pxr import UsdGeom

    st = _base(str(tmp_path / f"still_{y:g}.usda"))
    UsdGeom.Xformable(st.GetPrimAtPath("/World/Occluder")).AddTranslateYOp().Set(float(y))
    return _save(st)


def _v(path_or_scene, technique="hard", **kw):
    return wsoft.render(path_or_scene, technique, width=W, height=H, device="cpu", **kw).V


def test_a_spline_animated_occluder_moves_through_a_sequence(tmp_path):
    """translateY authored only as a spline (0 at 0, 2 at 10) and no time range: frames 0, 5, 10
    show the occluder at 0, 1 and 2 (as a still stage places it), no 'same stage' warning; the
    stage's range is its knots' span, 0..10."""
    from pxr import UsdGeom

    st = _base(str(tmp_path / "spline.usda"))
    _spline(UsdGeom.Xformable(st.GetPrimAtPath("/World/Occluder")).AddTranslateYOp().GetAttr(), [(0, 0), (10, 2)])
    p = _save(st)
    seq = render_sequence(p, "hard", frames="0:10:5", width=W, height=H, device="cpu")
    assert not any("same stage" in w for w in seq.warnings), seq.warnings
    assert [s["scene"] for s in seq.stats] != ["built", "reused", "reused"]
    for fr, y in zip(seq.frames, (0, 1, 2)):
        assert np.array_equal(fr.V, _v(_occluder_at_y(tmp_path, y)))
    assert not np.array_equal(seq[0].V, seq[2].V)
    with pytest.raises(ParameterError, match=r"outside the stage's time range \[0, 10\] \(its first and last time sample or spline knot"):
        render_sequence(p, "hard", frames="0:20:10", width=W, height=H, device="cpu")
    scene = wsoft.load_scene(p)  # no time: the first knot, said in a warning
    assert scene.time == 0.0 and any("loaded at time code 0" in w for w in scene.warnings)
    stage = open_stage(p)
    assert stage_is_animated(stage) and not static_geometry(stage)


def test_spline_knots_are_in_stage_time_through_a_layer_offset(tmp_path):
    """A sublayer's spline knots at 0 and 10, offset by +100 and scaled by 2 into the root: the
    stage's earliest time is 100 and its range 100..120."""
    from pxr import Sdf, Usd, UsdGeom

    st = _base(str(tmp_path / "anim.usda"))
    _spline(UsdGeom.Xformable(st.GetPrimAtPath("/World/Occluder")).AddTranslateYOp().GetAttr(), [(0, 0), (10, 2)])
    _save(st)
    root = Usd.Stage.CreateNew(str(tmp_path / "root.usda"))
    root.GetRootLayer().subLayerPaths.append("./anim.usda")
    root.GetRootLayer().subLayerOffsets[0] = Sdf.LayerOffset(100, 2)
    root.GetRootLayer().Save()
    assert earliest_time_sample(open_stage(str(tmp_path / "root.usda"))) == 100.0
    with pytest.raises(ParameterError, match=r"outside the stage's time range \[100, 120\]"):
        render_sequence(str(tmp_path / "root.usda"), "hard", frames="100:130:30", width=W, height=H, device="cpu")


def _lamp_with_shade(path: str, moving: bool):
    """The base's light with an instanceable shade below it (a 2 x 2 plate 0.5 under the light,
    from a class prototype); ``moving``: the light's translate time-sampled, (3, 0, 3) at 0 and
    (-3, 0, 3) at 10, with a time range 0..10; else the light still at (-3, 0, 3)."""
    from pxr import Gf, UsdGeom

    st = _base(path)
    add_class_root(st, "/Prototypes")
    add_quad(st, "/Prototypes/Shade/Plate", (0, 0, 0), 1)
    add_instance(st, "/World/Light/Shade", "/Prototypes/Shade", (0, 0, -0.5))
    (op,) = UsdGeom.Xformable(st.GetPrimAtPath("/World/Light")).GetOrderedXformOps()
    if moving:
        op.GetAttr().ClearDefault()
        op.Set(Gf.Vec3d(3, 0, 3), 0.0)
        op.Set(Gf.Vec3d(-3, 0, 3), 10.0)
        st.SetStartTimeCode(0)
        st.SetEndTimeCode(10)
    else:
        op.Set(Gf.Vec3d(-3, 0, 3))
    return _save(st)


@pytest.mark.parametrize("instancing", ["flatten", "keep"])
def test_an_instanced_shade_moves_with_its_animated_light(tmp_path, instancing):
    """A lamp whose shade is an instance below the animated light: the last frame is the still
    lamp's at the light's last place (the shade under it, the ground below in its umbra)."""
    p = _lamp_with_shade(str(tmp_path / "lamp.usda"), moving=True)
    assert not static_geometry(open_stage(p))
    seq = render_sequence(p, ["hard", ("reference", {"samples": 4})], frames=[0, 10], width=W, height=H, device="cpu",
                          instancing=instancing, reseed=False)
    assert seq.stats[1]["scene"] != "reused"
    still = wsoft.render(_lamp_with_shade(str(tmp_path / "still.usda"), moving=False), ["hard", ("reference", {"samples": 4})],
                         width=W, height=H, device="cpu")
    for label in ("hard", "reference"):
        assert np.array_equal(seq[1][label].V, still[label].V), label
    below = seq[1]["reference"]
    assert below.V.min() == 0.0  # the umbra of the shade


def _velocity_stage(path: str, samples=(0, 10), velocity=9.6, time_range=None):
    """The base with the occluder's points time-sampled at ``samples`` (at 0 where the base has
    them, at 10 moved 2 along Y) and ``velocities`` of ``velocity`` units per second along Y
    (24 time codes per second) at each sample."""
    from pxr import Gf, UsdGeom

    st = _base(path)
    st.SetTimeCodesPerSecond(24)
    mesh = UsdGeom.Mesh(st.GetPrimAtPath("/World/Occluder"))
    pts = list(mesh.GetPointsAttr().Get())
    mesh.GetPointsAttr().ClearDefault()
    for t in samples:
        dy = 0.2 * t
        mesh.GetPointsAttr().Set([Gf.Vec3f(q[0], q[1] + dy, q[2]) for q in pts], float(t))
        mesh.GetVelocitiesAttr().Set([Gf.Vec3f(0, velocity, 0)] * len(pts), float(t))
    if time_range:
        st.SetStartTimeCode(time_range[0])
        st.SetEndTimeCode(time_range[1])
    return _save(st)


def test_points_between_samples_follow_their_velocities_as_usd_computes_them(tmp_path):
    """Points sampled at 0 and 10 (2 apart) with velocities of 9.6 units/s (0.4 per time code):
    at 5 USD extrapolates from the sample at 0 by velocity, to 2 (not the samples' midpoint 1)."""
    p = _velocity_stage(str(tmp_path / "vel.usda"))
    seq = render_sequence(p, "hard", frames="0:10:5", width=W, height=H, device="cpu")
    assert np.array_equal(seq[1].V, _v(_occluder_at_y(tmp_path, 2)))
    assert not np.array_equal(seq[1].V, _v(_occluder_at_y(tmp_path, 1)))
    assert np.array_equal(seq[2].V, _v(_occluder_at_y(tmp_path, 2)))


def test_one_sample_with_velocities_is_animated(tmp_path):
    """One points sample at 0 with velocities (no value varies by itself) and a time range 0..5:
    the occluder moves (at 5, by 2), the geometry is not static and the frames are not reused."""
    p = _velocity_stage(str(tmp_path / "vel1.usda"), samples=(0,), time_range=(0, 5))
    stage = open_stage(p)
    assert stage_is_animated(stage) and not static_geometry(stage)
    scene = wsoft.load_scene(p, time=5)
    assert scene.tri_dynamic is not None and scene.tri_dynamic[scene.tri_prim == scene.prims.index("/World/Occluder")].all()
    seq = render_sequence(p, "hard", frames=[0, 5], width=W, height=H, device="cpu")
    assert seq.stats[1]["scene"] != "reused"
    assert np.array_equal(seq[1].V, _v(_occluder_at_y(tmp_path, 2)))


def test_frames_outside_a_stage_without_a_time_range_are_refused_before_rendering(tmp_path):
    """A stage with no time range and nothing animated: any frames are a one-line error naming that
    (the CLI exits 2); time samples without a range: frames outside their span are refused, naming it."""
    from wsoft.cli import run_captured

    with pytest.raises(ParameterError, match="has no time range"):
        render_sequence(scene_path("box_plane.usda"), "hard", frames="100:200", width=W, height=H, device="cpu")
    rc, out, err = run_captured(["render", scene_path("box_plane.usda"), "-t", "hard", "--frames", "100:200", "--out", tmp_path / "o.exr"])
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "box_plane.usda" in err and "has no time range" in err, err
    assert not list(tmp_path.glob("o*.exr"))
    p = _velocity_stage(str(tmp_path / "vel.usda"), velocity=0.0)
    with pytest.raises(ParameterError, match=r"frames 100\.\.200 lie outside the stage's time range \[0, 10\]"):
        render_sequence(p, "hard", frames="100:200", width=W, height=H, device="cpu")
