"""The bundled animated stages (:mod:`wsoft.stages.scenes.animated`), read back through wsoft's
loader: each one's time range, what moves between two time codes and by how much, that the static
one does not change, that shadows are in view on its first and last frames, and that its generator
writes the committed file."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
from conftest import SCENES
from pxr import Sdf, Usd, UsdGeom

import wsoft
from wsoft.pipeline import frame_setup, load_stage
from wsoft.stages.bundled import SCENES as GENERATORS
from wsoft.stages.scenes import animated

# name -> (base stage file, first frame, last frame)
ANIMATED = {
    "city_flyby": ("city.usdc", 1, 48),
    "bridge_sun_sweep": ("lightmapped_bridge.usda", 1, 48),
    "ramp_slide": ("penumbra_ramp.usda", 1, 48),
    "ramp_static": ("penumbra_ramp.usda", 1, 24),
}


def path(name: str) -> str:
    return SCENES + "/" + name + ".usda"


def angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.degrees(math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0)))


def light(scene, light_path: str):
    (found,) = [lt for lt in scene.lights if lt.path == light_path]
    return found


@pytest.mark.parametrize("name", ANIMATED)
def test_time_range_and_base(name):
    base, f0, f1 = ANIMATED[name]
    stage = Usd.Stage.Open(path(name))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (f0, f1)
    assert stage.GetTimeCodesPerSecond() == 24.0 and stage.GetFramesPerSecond() == 24.0
    assert stage.GetRootLayer().subLayerPaths == ["./" + base]
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == "/World"
    scene = wsoft.load_scene(path(name), instancing=True)
    assert scene.time == f0 and not scene.warnings, scene.warnings


def test_city_flyby_camera_flies_and_turns():
    """The render settings pick the flying camera; between the first and last frame its eye follows
    the stated arc (240 units, 5.1 a frame) and its heading turns by 40 degrees."""
    f0, f1 = ANIMATED["city_flyby"][1:]
    cams = {}
    for t in (f0, f0 + 1, f1):
        scene = load_stage(path("city_flyby"), time=t, instancing="keep")
        framing = frame_setup(scene)
        assert (framing.camera.path, framing.camera_source) == (animated.FLY_CAMERA, "render settings")
        assert (framing.width, framing.height) == animated.FLY_RESOLUTION
        cams[t] = framing.camera.to_world
    eye = {t: m[:3, 3] for t, m in cams.items()}
    forward = {t: -m[:3, 2] for t, m in cams.items()}
    np.testing.assert_allclose(eye[f0], (-150.0, -110.0, 85.0), atol=1e-6)
    assert eye[f1][2] == pytest.approx(70.0)
    step = np.linalg.norm(eye[f0 + 1][:2] - eye[f0][:2])  # over the ground: a chord of the arc
    assert step == pytest.approx(animated.FLY_PATH_LENGTH / (f1 - f0), rel=1e-4)
    assert eye[f0][2] - eye[f0 + 1][2] == pytest.approx(15.0 / (f1 - f0))
    assert np.linalg.norm(eye[f1] - eye[f0]) > 200.0
    heading = {t: math.degrees(math.atan2(v[1], v[0])) for t, v in forward.items()}
    assert heading[f0] == pytest.approx(15.0, abs=1e-6) and heading[f1] == pytest.approx(55.0, abs=1e-6)
    for t, v in forward.items():  # looking down at the ground ahead
        assert v[2] < -0.4, t


def test_city_flyby_stays_clear_of_the_buildings():
    """At every frame the eye is outside every building's bounds, by more than 5 units."""
    stage = Usd.Stage.Open(path("city_flyby"))
    cache = UsdGeom.BBoxCache(Usd.TimeCode.Default(), ["default", "render"])
    boxes = [cache.ComputeWorldBound(p).ComputeAlignedRange() for p in stage.GetPrimAtPath("/World/City").GetChildren()]
    lo = np.array([list(b.GetMin()) for b in boxes])
    hi = np.array([list(b.GetMax()) for b in boxes])
    assert len(boxes) == 344 and hi[:, 2].max() > 100.0  # towers taller than the flight
    cam = UsdGeom.Xformable(stage.GetPrimAtPath(animated.FLY_CAMERA))
    for f in range(int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode()) + 1):
        e = np.array(cam.ComputeLocalToWorldTransform(Usd.TimeCode(f)).ExtractTranslation())
        gap = np.linalg.norm(np.maximum(0.0, np.maximum(lo - e, e - hi)), axis=1)
        assert gap.min() > 5.0, (f, gap.min())


def test_bridge_sun_sweep_turns_the_sun_by_30_degrees():
    """The sun turns by 30 degrees from its base direction (the one the bake used) while the
    character walks."""
    f0, f1 = ANIMATED["bridge_sun_sweep"][1:]
    base = wsoft.load_scene(SCENES + "/lightmapped_bridge.usda")
    a, b = (wsoft.load_scene(path("bridge_sun_sweep"), time=t) for t in (f0, f1))
    sun = {k: -light(s, "/World/Lights/Sun").frame[:, 2] for k, s in (("base", base), ("a", a), ("b", b))}
    assert angle_deg(sun["base"], sun["a"]) < 1e-4
    assert angle_deg(sun["a"], sun["b"]) == pytest.approx(30.0, abs=1e-3)
    down = (0.0, 0.0, -1.0)
    assert angle_deg(sun["a"], down) == pytest.approx(18.0, abs=1e-3) and angle_deg(sun["b"], down) == pytest.approx(48.0, abs=1e-3)
    moved = [p for p in a.prims if p.startswith("/World/Dynamic/Character")]
    assert moved and not np.array_equal(a.points, b.points)  # the character walks
    np.testing.assert_array_equal(light(a, "/World/Lights/Torch").position, light(b, "/World/Lights/Torch").position)


def test_ramp_slide_moves_the_light_1_5_along_x():
    f0, f1 = ANIMATED["ramp_slide"][1:]
    lights = {t: light(wsoft.load_scene(path("ramp_slide"), time=t), "/World/Light") for t in (f0, f0 + 1, f1)}
    np.testing.assert_allclose(lights[f0].position, (-0.75, 0.0, 6.0), atol=1e-9)
    np.testing.assert_allclose(lights[f1].position, (0.75, 0.0, 6.0), atol=1e-9)
    np.testing.assert_allclose(lights[f0 + 1].position - lights[f0].position, (1.5 / (f1 - f0), 0.0, 0.0), atol=1e-9)
    for lt in lights.values():  # sliding, not turning: parallel to the plates
        np.testing.assert_allclose(lt.frame, np.eye(3), atol=1e-12)
        assert lt.half_size == (0.75, 0.75)


def test_ramp_static_does_not_change():
    f0, f1 = ANIMATED["ramp_static"][1:]
    stage = Usd.Stage.Open(path("ramp_static"))
    assert not any(layer.ListAllTimeSamples() for layer in stage.GetUsedLayers())
    a, b = (wsoft.load_scene(path("ramp_static"), time=t) for t in (f0, f1))
    assert a.time == f0 and b.time == f1
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    for la, lb in zip(a.lights, b.lights, strict=True):
        np.testing.assert_array_equal(la.position, lb.position)
        np.testing.assert_array_equal(la.frame, lb.frame)
    np.testing.assert_array_equal(a.cameras[0].to_world, b.cameras[0].to_world)
    va, vb = (wsoft.render(s, "hard", width=64, height=48, device="cpu")["V"] for s in (a, b))
    np.testing.assert_array_equal(va, vb)


@pytest.mark.parametrize("name", ANIMATED)
def test_shadows_in_view_on_first_and_last_frames(name):
    """The first light's V over the covered pixels has both lit (> 0.9) and shadowed (< 0.1)
    pixels; with the light moving, the two frames differ."""
    _, f0, f1 = ANIMATED[name]
    vs = []
    for t in (f0, f1):
        f = wsoft.render(load_stage(path(name), time=t), "hard", width=64, height=48, device="cpu")
        covered = f["A"] > 0.5
        v = f["V"][covered]
        assert covered.mean() > 0.3, (name, t)
        assert (v > 0.9).sum() >= 10 and (v < 0.1).sum() >= 10, (name, t, (v > 0.9).sum(), (v < 0.1).sum())
        vs.append(f["V"])
    assert np.array_equal(vs[0], vs[1]) == (name == "ramp_static")


def test_generators_write_the_committed_files(tmp_path):
    """Into a folder holding the base stages, each generator writes the committed layer, the same
    bytes on a second run; the stage it writes resolves its sublayer from that folder."""
    for name, (base, _, _) in ANIMATED.items():
        shutil.copy(SCENES + "/" + base, tmp_path / base)
    for name in ANIMATED:
        info = GENERATORS[name](str(tmp_path))
        new = tmp_path / (name + ".usda")
        assert info["file"] == str(new)
        first = new.read_bytes()
        GENERATORS[name](str(tmp_path))
        assert new.read_bytes() == first, name
        assert Sdf.Layer.OpenAsAnonymous(str(new)).ExportToString() == Sdf.Layer.OpenAsAnonymous(path(name)).ExportToString(), name
    assert GENERATORS["city_flyby"](str(tmp_path))["triangles"] == 1_041_866
    assert GENERATORS["ramp_slide"](str(tmp_path))["triangles"] == 62


def test_a_generator_writes_its_missing_base(tmp_path):
    """Into an empty folder, ramp_static's generator writes penumbra_ramp.usda too, and the stage
    loads from there."""
    GENERATORS["ramp_static"](str(tmp_path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["penumbra_ramp.usda", "ramp_static.usda"]
    scene = wsoft.load_scene(str(tmp_path / "ramp_static.usda"))
    assert scene.triangle_count == 62 and [lt.path for lt in scene.lights] == ["/World/Light"] and not scene.warnings
