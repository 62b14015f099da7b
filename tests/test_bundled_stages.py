"""``python -m wsoft.stages.bundled`` writes the committed bundled stages: the scenes built without
random numbers come out with the same layer text as the files in ``usd_scenes/``, their textures
byte for byte."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, SCENES
from pxr import Sdf

from wsoft.stages.bundled import SCENES as GENERATORS

# no random numbers: the same on every numpy (a Generator's streams may change between versions)
PLAIN = ("box_plane", "contact", "multi_light", "cutout", "penumbra_ramp", "tower", "tunnel_fan", "fence_perforated",
         "wedge_overlap", "ramp_slide", "ramp_static", "room_lamp", "corridor_torch", "walker", "dome_uniform", "dusk_street")


def test_every_bundled_stage_has_a_generator():
    from wsoft import usd_scenes

    assert sorted(GENERATORS) == usd_scenes.names()


def test_plain_stages_regenerate_as_committed(tmp_path):
    r = subprocess.run([sys.executable, "-m", "wsoft.stages.bundled", "--out", str(tmp_path), *PLAIN],
                       capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert len(r.stdout.splitlines()) == len(PLAIN)
    for name in PLAIN:
        (new,) = tmp_path.glob(name + ".usd*")
        old = SCENES + "/" + new.name
        assert Sdf.Layer.OpenAsAnonymous(str(new)).ExportToString() == Sdf.Layer.OpenAsAnonymous(old).ExportToString(), name
    written = sorted(p.name for p in (tmp_path / "textures").iterdir())
    assert written == ["checker_alpha.png", "dusk_sky.hdr", "fence_alpha.png"]
    for png in written:
        assert (tmp_path / "textures" / png).read_bytes() == open(SCENES + "/textures/" + png, "rb").read(), png


def test_unknown_scene_is_refused(capsys):
    from wsoft.stages.bundled import main

    with pytest.raises(SystemExit) as exc:
        main(["--out", "/nonexistent", "no_such_scene"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "unknown scene 'no_such_scene'" in err and "Traceback" not in err


@pytest.mark.parametrize("name", PLAIN)
def test_plain_generators_use_no_random_numbers(name, tmp_path, monkeypatch):
    """The scenes compared above are the ones whose generators never draw a random number."""
    import numpy as np

    def refuse(*a, **k):
        raise AssertionError("random numbers drawn")

    monkeypatch.setattr(np.random, "default_rng", refuse)
    GENERATORS[name](str(tmp_path))


@pytest.mark.parametrize("name", ["room_lamp", "corridor_torch"])
def test_interiors_surround_their_light_and_render_without_nan(name):
    """A light inside a closed room or corridor: receivers the camera sees lie on every side of it
    (below, above, beyond and before it along the camera's view), and ``hard`` and the
    reference render a small frame of it with no NaN, some of it lit and some in shadow."""
    import warnings

    import numpy as np

    import wsoft
    from wsoft.pipeline import load_stage

    scene = load_stage(name)
    (light,) = scene.lights
    assert light.kind_name == "sphere" and len(scene.cameras) == 1
    lo, hi = scene.points.min(axis=0), scene.points.max(axis=0)
    assert np.all(lo < light.position) and np.all(light.position < hi)  # the light is inside the shell
    frames = {}
    for tech, params in (("hard", {"shadow_map_size": 256}), ("reference", {"samples": 8})):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # hard's single frustum leaves receivers beyond it lit, with a warning
            frames[tech] = wsoft.render(scene, tech, width=48, height=36, device="cpu", **params)
    for tech, f in frames.items():
        V = np.asarray(f.V)
        assert V.shape == (36, 48) and not np.isnan(V).any(), tech
    V = np.asarray(frames["reference"].V)
    assert (V > 0.99).mean() > 0.3 and (V < 0.01).mean() > 0.02, name
    # directions from the light to the visible receivers: some below, some above, some behind
    f = frames["reference"]
    P = np.stack([f["P.X"], f["P.Y"], f["P.Z"]], axis=-1)[f["A"] > 0.5]
    d = P - light.position
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert (d[:, 2] < -0.7).any() and (d[:, 2] > 0.7).any(), name
    ahead = d @ -np.asarray(scene.cameras[0].to_world, np.float64)[:3, 2]  # along the camera's view
    assert (ahead > 0.3).mean() > 0.1 and (ahead < -0.3).mean() > 0.1, name  # receivers beyond the light and before it


# -- open_world: a large world under the sun -----------------------------------------------------------


def _terrain_heights(stage, n: int):
    from pxr import UsdGeom

    p = np.asarray(UsdGeom.Mesh(stage.GetPrimAtPath("/World/Terrain")).GetPointsAttr().Get(), np.float64)
    return p, p[:, 2].reshape(n + 1, n + 1)


def test_open_world_is_a_large_world_kept_small_on_disk():
    """The committed stage: a 3 km heightfield of about 1M triangles, 10^4-10^5 instances on the
    ground, a sun of angle 0.53 degrees, the camera 2 m above the ground looking to the horizon, and
    a file of at most 8 MiB."""
    import os

    from pxr import Usd, UsdGeom, UsdLux

    from wsoft.stages.scenes import open_world as ow

    file = SCENES + "/open_world.usdc"
    assert os.path.getsize(file) <= 8 * 2 ** 20
    stage = Usd.Stage.Open(file)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Terrain"))
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    tris = int((counts - 2).sum())
    assert 0.9e6 <= tris <= 1.1e6
    pts, h = _terrain_heights(stage, ow.SIZES["full"].grid)
    assert np.ptp(pts[:, 0]) == pytest.approx(3000.0) and np.ptp(pts[:, 1]) == pytest.approx(3000.0)
    assert np.ptp(h) > 100.0  # hills, not a plane
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Scatter"))
    pos = np.asarray(pi.GetPositionsAttr().Get(), np.float64)
    proto = np.asarray(pi.GetProtoIndicesAttr().Get())
    assert 1e4 <= len(pos) <= 1e5 and set(proto.tolist()) == set(range(6))
    ground = ow.ground_z(h, pos[:, 0], pos[:, 1])
    assert np.abs(pos[:, 2] - (ground - 0.1)).max() < 0.01  # every instance stands on the terrain
    sun = UsdLux.DistantLight(stage.GetPrimAtPath("/World/Lights/Sun"))
    assert sun.GetAngleAttr().Get() == pytest.approx(0.53)
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera")).GetCamera(Usd.TimeCode.Default())
    m = np.asarray(cam.transform, np.float64)  # row vectors: the eye is the last row
    eye, fwd = m[3, :3], -m[2, :3]
    assert eye[2] - ow.ground_z(h, eye[:1], eye[1:2])[0] == pytest.approx(2.0, abs=1e-3)
    assert abs(math.degrees(math.asin(fwd[2]))) < 5.0  # toward the horizon
    assert (ow.HALF - eye[0]) > 2000.0 and cam.clippingRange.max >= 2000.0  # the far hills 2 km away are in range


def test_open_world_sequences_fly_and_turn_the_sun():
    """open_world_flyby: 48 frames, the eye 1.2 m a frame 2 m above the ground, the sun still;
    open_world_sunset: the same flight, the sun 14 degrees lower at the end."""
    from pxr import Usd, UsdGeom

    from wsoft.stages.builders import world_dir
    from wsoft.stages.scenes import open_world as ow

    fly = Usd.Stage.Open(SCENES + "/open_world_flyby.usda")
    sunset = Usd.Stage.Open(SCENES + "/open_world_sunset.usda")
    _, h = _terrain_heights(fly, ow.SIZES["full"].grid)
    for stage in (fly, sunset):
        assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1, 48)
        assert stage.GetRootLayer().subLayerPaths == ["./open_world.usdc"]
        cam = UsdGeom.Xformable(stage.GetPrimAtPath(ow.FLY_CAMERA))
        eyes = np.array([np.asarray(cam.ComputeLocalToWorldTransform(Usd.TimeCode(t)), np.float64)[3, :3] for t in (1, 2, 48)])
        assert np.linalg.norm(eyes[1, :2] - eyes[0, :2]) == pytest.approx(ow.FLY_STEP, rel=1e-3)
        assert eyes[2, 2] - ow.ground_z(h, eyes[2:, 0], eyes[2:, 1])[0] == pytest.approx(2.0, abs=1e-3)
    sun = lambda st, t: np.asarray(world_dir(st.GetPrimAtPath("/World/Lights/Sun")) if t is None else  # noqa: E731
                                   UsdGeom.Xformable(st.GetPrimAtPath("/World/Lights/Sun")).ComputeLocalToWorldTransform(Usd.TimeCode(t))
                                   .TransformDir((0, 0, -1)))
    assert np.allclose(sun(fly, 1), sun(fly, 48))
    elevation = [math.degrees(math.asin(-sun(sunset, t)[2] / np.linalg.norm(sun(sunset, t)))) for t in (1, 48)]
    assert elevation[0] == pytest.approx(28.0, abs=0.01) and elevation[1] == pytest.approx(14.0, abs=0.01)


def test_open_world_tiny_is_the_same_world_smaller(tmp_path):
    """The builder's tiny size writes the three stages with a 64 x 64 heightfield and a few hundred
    instances on it; an unknown size is refused."""
    from pxr import Usd, UsdGeom

    from wsoft.stages.scenes import open_world as ow

    files = ow.write_world(str(tmp_path), "tiny")
    assert sorted(files) == ["open_world", "open_world_flyby", "open_world_sunset"]
    stage = Usd.Stage.Open(files["open_world_sunset"])
    size = ow.SIZES["tiny"]
    pts, h = _terrain_heights(stage, size.grid)
    assert len(pts) == (size.grid + 1) ** 2 and np.ptp(pts[:, 0]) == pytest.approx(2 * ow.HALF)
    pos = np.asarray(UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Scatter")).GetPositionsAttr().Get(), np.float64)
    assert 0.8 * (size.scattered + size.near + size.houses) < len(pos) <= size.scattered + size.near + size.houses
    assert np.abs(pos[:, 2] - (ow.ground_z(h, pos[:, 0], pos[:, 1]) - 0.1)).max() < 0.01
    with pytest.raises(ValueError, match="not one of full, tiny"):
        ow.write_world(str(tmp_path), "huge")


@pytest.mark.slow
def test_open_world_tiny_loads_and_renders(tmp_path):
    """The tiny stage through wsoft's loader (instances kept), lit by its sun: a small hard frame of
    it is finite, with sun and shadow."""
    import wsoft
    from wsoft.pipeline import load_stage
    from wsoft.stages.scenes import open_world as ow

    scene = load_stage(ow.write_world(str(tmp_path), "tiny")["open_world"], instancing="keep")
    assert scene.instanced and scene.total_triangles > 2 * ow.SIZES["tiny"].grid ** 2 and not scene.warnings
    (sun,) = scene.lights
    assert sun.kind_name == "distant"
    f = wsoft.render(scene, "hard", width=40, height=30, device="cpu", shadow_map_size=256)
    V = np.asarray(f.V)[np.asarray(f["A"]) > 0.5]
    assert np.isfinite(V).all() and (V > 0.99).mean() > 0.2 and (V < 0.01).mean() > 0.01
