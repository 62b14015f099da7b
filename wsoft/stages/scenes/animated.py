"""Animated stages for measuring shadows in motion (flicker, crawl, shimmer): ``city_flyby``,
``bridge_sun_sweep``, ``ramp_slide`` and ``ramp_static``.

Each is a small ``.usda`` that sublayers a bundled stage (``./city.usdc``, ...: a path relative to
itself, so it resolves wherever the folder is installed) and adds what moves, one time sample per
frame (time code), at 24 time codes per second. Its layer repeats the stage metadata (up axis,
``metersPerUnit``, default prim), which a stage reads from its root layer only. A generator writes
the stage it sublayers into the same folder first when it is not there. ``/World``'s
``wsoft:doc:motion`` says what moves and by how much (the base stage's ``wsoft:doc`` stays).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdRender

from wsoft.stages.builders import look_at_xform, set_doc_string
from wsoft.stages.scenes import APERTURES, basics, bridge, city

FPS = 24.0

# city_flyby: the camera flies a left turn at constant speed over the middle of the city, its
# heading (degrees from +X) going from FLY_HEADING[0] to FLY_HEADING[1], descending from
# FLY_ALTITUDE[0] to FLY_ALTITUDE[1]; it looks at the ground FLY_LOOK_AHEAD ahead along its heading.
# The headings are about square to the sun's horizontal direction (toward -x, +y), so the
# buildings' shadows fall across the view.
FLY_FRAMES = (1, 48)
FLY_START = (-150.0, -110.0)
FLY_HEADING = (15.0, 55.0)
FLY_PATH_LENGTH = 240.0
FLY_ALTITUDE = (85.0, 70.0)
FLY_LOOK_AHEAD = 140.0
FLY_FOCAL = 24.0
FLY_RESOLUTION = (320, 240)
FLY_CAMERA = "/World/FlyCamera"
FLY_SETTINGS = "/Render/FlyBy"

# bridge_sun_sweep: the sun's rotateXYZ (18, 0, 117) of lightmapped_bridge, its X rotation (the
# tilt from straight down) swept linearly over the character's walk
SUN_TILT = (18.0, 48.0)
SUN_ROTATE_YZ = (0.0, 117.0)

# ramp_slide: penumbra_ramp's light (at (0, 0, 6)) slides along +x
SLIDE_FRAMES = (1, 48)
SLIDE_X = (-0.75, 0.75)
STATIC_FRAMES = (1, 24)


def frame_fraction(frames: tuple[int, int]) -> list[tuple[int, float]]:
    """Each frame (time code) of ``frames`` (first, last) and its fraction of the way, 0 to 1."""
    f0, f1 = frames
    return [(f, (f - f0) / (f1 - f0)) for f in range(f0, f1 + 1)]


def fly_path(s: float) -> tuple[np.ndarray, np.ndarray]:
    """``city_flyby``'s camera at the fraction ``s`` of its flight: its eye and the ground point it
    looks at."""
    h0, h1 = (math.radians(h) for h in FLY_HEADING)
    radius = FLY_PATH_LENGTH / (h1 - h0)
    h = h0 + s * (h1 - h0)
    x = FLY_START[0] + radius * (math.sin(h) - math.sin(h0))
    y = FLY_START[1] - radius * (math.cos(h) - math.cos(h0))
    z = FLY_ALTITUDE[0] + s * (FLY_ALTITUDE[1] - FLY_ALTITUDE[0])
    eye = np.array([x, y, z])
    target = np.array([x + FLY_LOOK_AHEAD * math.cos(h), y + FLY_LOOK_AHEAD * math.sin(h), 0.0])
    return eye, target


def sun_rotate(s: float) -> tuple[float, float, float]:
    """``bridge_sun_sweep``'s sun rotateXYZ (degrees) at the fraction ``s`` of the sweep."""
    return (SUN_TILT[0] + s * (SUN_TILT[1] - SUN_TILT[0]), *SUN_ROTATE_YZ)


def over_stage(base: Usd.Stage, frames: tuple[int, int]) -> Usd.Stage:
    """A stage in memory holding the stage metadata of ``base`` (up axis, ``metersPerUnit``) and
    the time range ``frames`` at :data:`FPS`, and an ``over`` of ``/World``."""
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.GetStageUpAxis(base))
    UsdGeom.SetStageMetersPerUnit(stage, UsdGeom.GetStageMetersPerUnit(base))
    stage.SetDefaultPrim(stage.OverridePrim("/World"))
    stage.SetStartTimeCode(frames[0])
    stage.SetEndTimeCode(frames[1])
    stage.SetTimeCodesPerSecond(FPS)
    stage.SetFramesPerSecond(FPS)
    return stage


def base_stage(out_dir: str, name: str, generate: Callable[[str], dict[str, object]]) -> tuple[str, Usd.Stage]:
    """The file name of the bundled stage ``name`` in ``out_dir`` (written by ``generate`` when it
    is not there) and that stage, opened."""
    found = [f for f in (name + ".usda", name + ".usdc") if os.path.isfile(os.path.join(out_dir, f))]
    file = found[0] if found else os.path.basename(str(generate(out_dir)["file"]))
    return file, Usd.Stage.Open(os.path.join(out_dir, file))


def write_over(stage: Usd.Stage, base_file: str, path: str) -> None:
    """Write the root layer of ``stage`` to ``path``, sublayering ``./base_file``."""
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.TransferContent(stage.GetRootLayer())
    layer.GetPrimAtPath("/World").specifier = Sdf.SpecifierOver  # defining a child there made it a def
    layer.subLayerPaths.append("./" + base_file)
    if os.path.exists(path):
        os.remove(path)
    layer.Export(path)


def stage_triangles(path: str) -> int:
    """Triangles of every mesh of the stage at ``path`` (instances through their proxies; a face of
    n vertices counts n - 2)."""
    total = 0
    stage = Usd.Stage.Open(path)
    for prim in Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies()):
        if prim.IsA(UsdGeom.Mesh):
            total += int(np.sum(np.asarray(UsdGeom.Mesh(prim).GetFaceVertexCountsAttr().Get()) - 2))
    return total


def scene_city_flyby(out_dir: str) -> dict[str, object]:
    """``city`` seen from a camera flying low over it and turning: ``city_flyby.usda``."""
    path = os.path.join(out_dir, "city_flyby.usda")
    base_file, base = base_stage(out_dir, "city", city.scene_city)
    stage = over_stage(base, FLY_FRAMES)
    eyes = [fly_path(s)[0] for _, s in frame_fraction(FLY_FRAMES)]
    step = float(np.linalg.norm(eyes[1] - eyes[0]))
    turn = (FLY_HEADING[1] - FLY_HEADING[0]) / (FLY_FRAMES[1] - FLY_FRAMES[0])
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc:motion", (
        "A camera flying low over the city under its sun (the shadow-map shimmer case: the view "
        "translates and turns every frame). %s sublayers %s and adds the camera %s, used through the "
        "render settings %s (%d x %d). Frames %d to %d at %g fps, one look-at transform per frame: "
        "the eye flies a left turn %g units long over the ground, %.3g units per frame, its heading going from %g to "
        "%g degrees from +x (%.3g degrees per frame) and its height from %g down to %g, clear of "
        "every building; it looks at the ground %g ahead. The sun's shadows fall toward -x, +y, "
        "across the view. The city's RectLight stays: pick the sun with --light /World/Lights/Sun."
        % ("city_flyby.usda", base_file, FLY_CAMERA, FLY_SETTINGS, *FLY_RESOLUTION, *FLY_FRAMES, FPS,
           FLY_PATH_LENGTH, step, *FLY_HEADING, turn, *FLY_ALTITUDE, FLY_LOOK_AHEAD)))

    cam = UsdGeom.Camera.Define(stage, FLY_CAMERA)
    cam.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    cam.CreateFocalLengthAttr(FLY_FOCAL)
    cam.CreateHorizontalApertureAttr(APERTURES["4:3"][0])
    cam.CreateVerticalApertureAttr(APERTURES["4:3"][1])
    cam.CreateClippingRangeAttr(Gf.Vec2f(1.0, 5000.0))
    op = cam.AddTransformOp()
    for f, s in frame_fraction(FLY_FRAMES):
        eye, target = fly_path(s)
        op.Set(look_at_xform(eye, target, (0.0, 0.0, 1.0)), Usd.TimeCode(f))

    settings = UsdRender.Settings.Define(stage, FLY_SETTINGS)
    settings.CreateResolutionAttr(Gf.Vec2i(*FLY_RESOLUTION))
    settings.CreateCameraRel().SetTargets([Sdf.Path(FLY_CAMERA)])
    stage.SetMetadata("renderSettingsPrimPath", FLY_SETTINGS)

    write_over(stage, base_file, path)
    return {"file": path, "triangles": stage_triangles(path)}


def scene_bridge_sun_sweep(out_dir: str) -> dict[str, object]:
    """``lightmapped_bridge`` with its sun swept while the character walks: ``bridge_sun_sweep.usda``."""
    path = os.path.join(out_dir, "bridge_sun_sweep.usda")
    base_file, base = base_stage(out_dir, "lightmapped_bridge", bridge.scene_lightmapped_bridge)
    stage = over_stage(base, bridge.BRIDGE_FRAMES)
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc:motion", (
        "lightmapped_bridge with its sun swept while the character walks along the deck (frames "
        "%d to %d at %g fps). %s sublayers %s; /World/Lights/Sun's rotateXYZ goes linearly from "
        "(%g, %g, %g) to (%g, %g, %g), one sample per frame: its direction turns by %g degrees, from "
        "%g to %g degrees off straight down, so the shadows lengthen. The baked light of the static "
        "meshes is the base stage's, for the sun at its first frame."
        % (*bridge.BRIDGE_FRAMES, FPS, "bridge_sun_sweep.usda", base_file, *sun_rotate(0.0), *sun_rotate(1.0),
           SUN_TILT[1] - SUN_TILT[0], *SUN_TILT)))
    sun = stage.OverridePrim("/World/Lights/Sun")
    attr = sun.CreateAttribute("xformOp:rotateXYZ", Sdf.ValueTypeNames.Float3, custom=False)
    for f, s in frame_fraction(bridge.BRIDGE_FRAMES):
        attr.Set(Gf.Vec3f(*sun_rotate(s)), Usd.TimeCode(f))
    write_over(stage, base_file, path)
    return {"file": path, "triangles": stage_triangles(path)}


def scene_ramp_slide(out_dir: str) -> dict[str, object]:
    """``penumbra_ramp`` with its rect light sliding along x: ``ramp_slide.usda``."""
    path = os.path.join(out_dir, "ramp_slide.usda")
    base_file, base = base_stage(out_dir, "penumbra_ramp", basics.scene_penumbra_ramp)
    stage = over_stage(base, SLIDE_FRAMES)
    z = basics.PENUMBRA_LIGHT_Z
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc:motion", (
        "penumbra_ramp with its rect light sliding along +x, the camera still (frames %d to %d at "
        "%g fps). %s sublayers %s; /World/Light's translate goes linearly from (%g, 0, %g) to "
        "(%g, 0, %g), %g per frame. The light stays parallel to the plates and the ground, so the "
        "penumbra widths are the base stage's; each shadow moves by -(x light) * z / (6 - z)."
        % (*SLIDE_FRAMES, FPS, "ramp_slide.usda", base_file, SLIDE_X[0], z, SLIDE_X[1], z,
           (SLIDE_X[1] - SLIDE_X[0]) / (SLIDE_FRAMES[1] - SLIDE_FRAMES[0]))))
    light = stage.OverridePrim("/World/Light")
    attr = light.CreateAttribute("xformOp:translate", Sdf.ValueTypeNames.Double3, custom=False)
    for f, s in frame_fraction(SLIDE_FRAMES):
        attr.Set(Gf.Vec3d(SLIDE_X[0] + s * (SLIDE_X[1] - SLIDE_X[0]), 0.0, z), Usd.TimeCode(f))
    write_over(stage, base_file, path)
    return {"file": path, "triangles": stage_triangles(path)}


def scene_ramp_static(out_dir: str) -> dict[str, object]:
    """``penumbra_ramp`` over a time range with nothing moving: ``ramp_static.usda``."""
    path = os.path.join(out_dir, "ramp_static.usda")
    base_file, base = base_stage(out_dir, "penumbra_ramp", basics.scene_penumbra_ramp)
    stage = over_stage(base, STATIC_FRAMES)
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc:motion", (
        "penumbra_ramp over frames %d to %d at %g fps with nothing animated: every frame is the same "
        "scene, so what changes between frames is a technique's own (the crawl of a stochastic one). "
        "%s sublayers %s." % (*STATIC_FRAMES, FPS, "ramp_static.usda", base_file)))
    write_over(stage, base_file, path)
    return {"file": path, "triangles": stage_triangles(path)}
