"""The adversarial corpus: stages a new or a hostile user feeds wsoft, and what each must give.

Every case writes a small stage (or a broken file) into a folder and says what is expected of
every technique that supports it: ``ok`` (exit 0, no NaN, and where the answer is known, the
answer: full shadow under a lamp shade, the occluder's shadow unchanged by a far huge triangle)
or ``error`` (exit 2, one line naming the file and the prim, no traceback). Warnings a case must
raise are listed too. :func:`judge` tells what is wrong with a result; the expectations hold at
the frame size and settings below.

The sweep ``wsoft bench adversarial`` (``wsoft.bench.adversarial``) runs every case through the
command line in-process, exactly as a user runs them (``wsoft render STAGE -t TECH --out ...
--stats ...``), and ``tests/test_adversarial.py`` runs it on CPU in CI.
"""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from wsoft.stages.builders import add_box, add_camera, add_mesh, add_quad, add_rect_light, add_sun, make_stage

W, H = 48, 36  # frame size of every case (small: the corpus runs in CI)
MAP = 256  # texels (cells) per side of every technique's light map or grid (its size_param)
REF_SAMPLES = 64

# --------------------------------------------------------------------------- stage builders


def _save(stage, folder: str, name: str, ext: str = ".usda") -> str:
    """Export ``stage`` as ``folder/name + ext``; its path."""
    path = os.path.join(folder, name + ext)
    stage.GetRootLayer().Export(path)
    return path


def _base(light: str = "rect"):
    """Ground, a square occluder and a light above it, seen by a camera: the shadow every
    'unchanged' case compares with."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_quad(st, "/World/Occluder", (0, 0, 1), 1)
    if light == "rect":
        add_rect_light(st, "/World/Light", (0, 0, 3), 1, 1)
    else:
        add_sun(st, "/World/Light", 2.0, (0, -20, 0))
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return st


def _triangle(st, path: str, pts):
    """One triangle through ``pts`` (a minimal mesh)."""
    return add_mesh(st, path, (pts, [3], [0, 1, 2]), minimal=True)


def _sphere_mesh(st, path: str, center, radius: float, n: int = 16):
    """A closed, outward-wound UV sphere (a minimal mesh)."""
    pts = [(center[0], center[1], center[2] - radius)]
    for i in range(1, n):
        th = np.pi * i / n - np.pi / 2
        for j in range(2 * n):
            ph = np.pi * j / n
            pts.append((center[0] + radius * np.cos(th) * np.cos(ph), center[1] + radius * np.cos(th) * np.sin(ph), center[2] + radius * np.sin(th)))
    pts.append((center[0], center[1], center[2] + radius))
    top = len(pts) - 1
    counts, idx = [], []
    ring = lambda i, j: 1 + (i - 1) * 2 * n + (j % (2 * n))  # noqa: E731
    for j in range(2 * n):
        counts.append(3)
        idx += [0, ring(1, j + 1), ring(1, j)]
    for i in range(1, n - 1):
        for j in range(2 * n):
            counts.append(4)
            idx += [ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)]
    for j in range(2 * n):
        counts.append(3)
        idx += [ring(n - 1, j), ring(n - 1, j + 1), top]
    return add_mesh(st, path, (np.asarray(pts, dtype=np.float64), counts, idx), minimal=True)


def _cutout_occluder(st, texture: str, channel: str = "a"):
    """The base occluder made a cutout through ``texture`` (a path relative to the stage)."""
    from pxr import Sdf, UsdShade

    mat = UsdShade.Material.Define(st, "/World/Looks/Cut")
    surf = UsdShade.Shader.Define(st, "/World/Looks/Cut/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(st, "/World/Looks/Cut/St")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    tex = UsdShade.Shader.Define(st, "/World/Looks/Cut/Alpha")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(texture)
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    out = tex.CreateOutput(channel, Sdf.ValueTypeNames.Float)
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(out)
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    occ = st.GetPrimAtPath("/World/Occluder")
    from pxr import UsdGeom

    pv = UsdGeom.PrimvarsAPI(occ).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    pv.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    UsdShade.MaterialBindingAPI.Apply(occ).Bind(mat)


def _checker(size: int = 8) -> np.ndarray:
    """A checker of opaque and transparent squares (1 = opaque), ``size`` x ``size`` texels."""
    i, j = np.indices((size, size))
    return ((i // (size // 4) + j // (size // 4)) % 2).astype(np.float64)


def _png(folder: str, name: str, alpha: np.ndarray, mode: str) -> str:
    from PIL import Image

    path = os.path.join(folder, name)
    if mode == "RGBA":
        a = (alpha * 255).astype(np.uint8)
        Image.fromarray(np.dstack([a, a, a, a]), "RGBA").save(path)
    elif mode == "I;16":
        Image.fromarray((alpha * 65535).astype(np.uint16)).save(path)  # 16-bit grey: opacity from outputs:r
    elif mode == "P":
        img = Image.fromarray((alpha * 255).astype(np.uint8), "L").convert("RGBA").convert("P")
        img.info["transparency"] = None
        img.save(path)
    return name


# each builder: folder -> stage path


def b_base(folder):
    return _save(_base(), folder, "base")


def b_base_sun(folder):
    return _save(_base("sun"), folder, "base_sun")


def b_lamp_rect(folder):
    """A rect light inside a closed box (a lamp shade) over a ground: all is in shadow."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_box(st, "/World/Shade", (-1, -1, 0.5), (1, 1, 2.5))
    add_rect_light(st, "/World/Light", (0, 0, 1.5), 0.5, 0.5)
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return _save(st, folder, "lamp_rect")


def b_lamp_sphere(folder):
    """A sphere light inside a closed box: shadow all around, beyond a single frustum's reach."""
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_box(st, "/World/Shade", (-1, -1, 0.5), (1, 1, 2.5))
    light = UsdLux.SphereLight.Define(st, "/World/Light")
    light.CreateRadiusAttr(0.2)
    UsdGeom.XformCommonAPI(light).SetTranslate(Gf.Vec3d(0, 0, 1.5))
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return _save(st, folder, "lamp_sphere")


def b_huge_far_triangle(folder):
    """The base plus one triangle with corners at +-1e7, below the ground and out of view."""
    st = _base()
    _triangle(st, "/World/Huge", [(-1e7, -1e7, -5000), (1e7, -1e7, -5000), (0, 1e7, -5000)])
    return _save(st, folder, "huge_far_triangle")


def b_huge_far_triangle_sun(folder):
    st = _base("sun")
    _triangle(st, "/World/Huge", [(-1e7, -1e7, -5000), (1e7, -1e7, -5000), (0, 1e7, -5000)])
    return _save(st, folder, "huge_far_triangle_sun")


def b_point_3e38(folder):
    """The base plus a sliver triangle reaching 3e38 (near float32's largest), out of view."""
    st = _base()
    _triangle(st, "/World/Huge", [(1e3, -1e3, -100), (1e3 + 1, -1e3, -100), (1e3, -3e38, -100)])
    return _save(st, folder, "point_3e38")


def b_points_1e30(folder):
    st = _base()
    _triangle(st, "/World/Far", [(1e30, 1e30, 1e30), (1e30 + 1e24, 1e30, 1e30), (1e30, 1e30 + 1e24, 1e30)])
    return _save(st, folder, "points_1e30")


def b_thin_plate_behind(folder):
    """A double-sided plate lit from behind, seen from the front: dark for everyone."""
    from pxr import Gf, UsdGeom

    st = make_stage()
    add_quad(st, "/World/Plate", (0, 0, 0), 2)
    light = add_rect_light(st, "/World/Light", (0, 0, -3), 1, 1)
    UsdGeom.XformCommonAPI(light).SetRotate(Gf.Vec3f(180, 0, 0))  # emits along +Z, toward the plate's back
    add_camera(st, "/World/Cam", (0, -3, 4), (0, 0, 0))
    return _save(st, folder, "thin_plate_behind")


def b_sphere(folder):
    """A closed sphere under a rect light: its far side is dark, its top lit."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, -1.2), 5)
    _sphere_mesh(st, "/World/Ball", (0, 0, 0), 1.0)
    add_rect_light(st, "/World/Light", (0, 0, 4), 1, 1)
    add_camera(st, "/World/Cam", (0, -5, 1.5), (0, 0, 0))
    return _save(st, folder, "sphere")


def b_light_on_receiver_plane(folder):
    st = _base()
    from pxr import Gf, UsdGeom

    UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/Light")).SetTranslate(Gf.Vec3d(0, 0, 0))
    return _save(st, folder, "light_on_receiver_plane")


def b_light_below_ground(folder):
    """The light under a single-sided ground: the ground's top never sees it."""
    st = _base()
    from pxr import Gf, UsdGeom

    xf = UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/Light"))
    xf.SetTranslate(Gf.Vec3d(0, 0, -3))
    xf.SetRotate(Gf.Vec3f(180, 0, 0))
    return _save(st, folder, "light_below_ground")


def b_mirrored(folder):
    """The base with the occluder mirrored (scale -1 in x): the same shadow."""
    from pxr import Gf, UsdGeom

    st = _base()
    UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/Occluder")).SetScale(Gf.Vec3f(-1, 1, 1))
    return _save(st, folder, "mirrored")


def b_zero_area(folder):
    """The base plus degenerate triangles (repeated and collinear corners)."""
    st = _base()
    add_mesh(st, "/World/Degenerate", ([(0, 0, 2), (0, 0, 2), (1, 1, 2), (2, 2, 2)], [3, 3], [0, 1, 2, 0, 2, 3]), minimal=True)
    return _save(st, folder, "zero_area")


def b_camera_inside(folder):
    st = _base()
    add_box(st, "/World/Room", (-5.5, -6.5, -0.5), (5.5, 5.5, 5.5))
    return _save(st, folder, "camera_inside")


def b_usdc(folder):
    return _save(_base(), folder, "base_binary", ".usdc")


def _cutout_stage(folder, name, texture, channel="a"):
    st = _base()
    _cutout_occluder(st, texture, channel)
    return _save(st, folder, name)


def b_cutout_8bit(folder):
    return _cutout_stage(folder, "cutout_8bit", _png(folder, "checker8.png", _checker(), "RGBA"))


def b_cutout_16bit(folder):
    return _cutout_stage(folder, "cutout_16bit", _png(folder, "checker16.png", _checker(), "I;16"), channel="r")


def b_cutout_palette(folder):
    return _cutout_stage(folder, "cutout_palette", _png(folder, "checker_p.png", _checker(), "P"), channel="r")


def b_cutout_1x1(folder):
    """A 1x1 fully transparent texture: the occluder is cut away entirely."""
    return _cutout_stage(folder, "cutout_1x1", _png(folder, "clear1.png", np.zeros((1, 1)), "RGBA"))


def b_no_occluder(folder):
    st = _base()
    st.RemovePrim("/World/Occluder")
    return _save(st, folder, "no_occluder")


def b_cutout_usdz(folder):
    """The 8-bit cutout stage packaged as a .usdz (its texture inside the package)."""
    from pxr import Sdf, UsdUtils

    sub = os.path.join(folder, "pkg")
    os.makedirs(sub, exist_ok=True)
    src = _cutout_stage(sub, "cutout_pkg", _png(sub, "checker8.png", _checker(), "RGBA"))
    out = os.path.join(folder, "cutout_pkg.usdz")
    with contextlib.suppress(FileNotFoundError):
        os.remove(out)
    if not UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(src), out):
        raise RuntimeError("cannot build the .usdz package")
    return out


def b_cutout_truncated_png(folder):
    name = _png(folder, "truncated.png", _checker(64), "RGBA")
    data = open(os.path.join(folder, name), "rb").read()
    with open(os.path.join(folder, name), "wb") as f:
        f.write(data[: len(data) // 2])
    return _cutout_stage(folder, "cutout_truncated_png", name)


def b_zero_width_rect(folder):
    st = _base()
    st.GetPrimAtPath("/World/Light").GetAttribute("inputs:width").Set(0.0)
    return _save(st, folder, "zero_width_rect")


def b_inverted_clip(folder):
    from pxr import Gf

    st = _base()
    st.GetPrimAtPath("/World/Cam").GetAttribute("clippingRange").Set(Gf.Vec2f(1000, 0.01))
    return _save(st, folder, "inverted_clip")


def b_missing_sublayer(folder):
    st = _base()
    st.GetRootLayer().subLayerPaths.append("./not_there.usda")
    return _save(st, folder, "missing_sublayer")


def b_missing_reference(folder):
    st = _base()
    st.DefinePrim("/World/Prop").GetReferences().AddReference("./no_such_asset.usda")
    return _save(st, folder, "missing_reference")


def _bad_light_attr(folder, name, make):
    st = _base()
    make(st)
    return _save(st, folder, name)


def b_rect_nan_width(folder):
    return _bad_light_attr(folder, "rect_nan_width", lambda st: st.GetPrimAtPath("/World/Light").GetAttribute("inputs:width").Set(float("nan")))


def b_rect_inf_width(folder):
    return _bad_light_attr(folder, "rect_inf_width", lambda st: st.GetPrimAtPath("/World/Light").GetAttribute("inputs:width").Set(float("inf")))


def _swap_light(st, kind: str, radius: float):
    from pxr import Gf, UsdGeom, UsdLux

    st.RemovePrim("/World/Light")
    light = (UsdLux.SphereLight if kind == "sphere" else UsdLux.DiskLight).Define(st, "/World/Light")
    light.CreateRadiusAttr(radius)
    UsdGeom.XformCommonAPI(light).SetTranslate(Gf.Vec3d(0, 0, 3))


def b_sphere_nan_radius(folder):
    return _bad_light_attr(folder, "sphere_nan_radius", lambda st: _swap_light(st, "sphere", float("nan")))


def b_disk_inf_radius(folder):
    return _bad_light_attr(folder, "disk_inf_radius", lambda st: _swap_light(st, "disk", float("inf")))


def b_disk_negative_radius(folder):
    return _bad_light_attr(folder, "disk_negative_radius", lambda st: _swap_light(st, "disk", -1.0))


def b_exposure_huge(folder):
    return _bad_light_attr(folder, "exposure_huge", lambda st: st.GetPrimAtPath("/World/Light").CreateAttribute(
        "inputs:exposure", __import__("pxr").Sdf.ValueTypeNames.Float).Set(1e6))


def _xform(st, op: str, value):
    from pxr import Gf, UsdGeom

    xf = UsdGeom.Xformable(st.GetPrimAtPath("/World/Occluder"))
    if op == "translate":
        xf.AddTranslateOp().Set(Gf.Vec3d(*value))
    else:
        xf.AddScaleOp().Set(Gf.Vec3f(*value))


def b_nan_transform(folder):
    return _bad_light_attr(folder, "nan_transform", lambda st: _xform(st, "translate", (float("nan"), 0, 0)))


def b_inf_transform(folder):
    return _bad_light_attr(folder, "inf_transform", lambda st: _xform(st, "scale", (float("inf"), 1, 1)))


def _counts(st, counts, idx):
    m = st.GetPrimAtPath("/World/Occluder")
    m.GetAttribute("faceVertexCounts").Set(counts)
    m.GetAttribute("faceVertexIndices").Set(idx)


def b_negative_count(folder):
    return _bad_light_attr(folder, "negative_count", lambda st: _counts(st, [-1, 4], [0, 1, 2]))


def b_count_5_minus_2(folder):
    return _bad_light_attr(folder, "count_5_minus_2", lambda st: _counts(st, [5, -2], [0, 1, 2]))


def b_broken_syntax(folder):
    path = os.path.join(folder, "broken_syntax.usda")
    with open(path, "w") as f:
        f.write('#usda 1.0\ndef Xform "World" {\n  def Mesh "M" {\n    int[] faceVertexCounts = [3\n  }\n}\n')
    return path


def b_empty(folder):
    return _save(make_stage(), folder, "empty")


def b_dome_only(folder):
    from pxr import UsdLux

    st = _base()
    st.RemovePrim("/World/Light")
    UsdLux.DomeLight.Define(st, "/World/Dome")
    return _save(st, folder, "dome_only")


# -- mesh topology and time samples (holeIndices, concave faces, samples without a time range)


def b_hole_face(folder):
    """The base with the occluder's only face listed in its ``holeIndices``: nothing casts."""
    st = _base()
    from pxr import UsdGeom

    UsdGeom.Mesh(st.GetPrimAtPath("/World/Occluder")).CreateHoleIndicesAttr([0])
    return _save(st, folder, "hole_face")


# a pentagon notched from above, its reflex corner (index 3) below the diagonal from corner 0: the
# fan from corner 0 covers part of the notch; the triangles that split it correctly, in the order
# and winding the loader's ear clipping gives them
_PENTAGON = [(-1, -1, 1), (1, -1, 1), (1, 1, 1), (0, -0.6, 1), (-1, 1, 1)]
_PENTAGON_SPLIT = [1, 2, 3, 0, 1, 3, 0, 3, 4]


def _pentagon_stage(counts, indices):
    st = _base()
    st.RemovePrim("/World/Occluder")
    add_mesh(st, "/World/Occluder", (_PENTAGON, counts, indices), double_sided=True, minimal=True)
    return st


def b_concave_pentagon(folder):
    """The occluder a concave pentagon, one face."""
    return _save(_pentagon_stage([5], [0, 1, 2, 3, 4]), folder, "concave_pentagon")


def b_concave_pentagon_split(folder):
    """The same pentagon authored as the three triangles that split it."""
    return _save(_pentagon_stage([3, 3, 3], _PENTAGON_SPLIT), folder, "concave_pentagon_split")


def b_base_dynamic(folder):
    """The base with its occluder marked ``wsoft:dynamic``: what an animated occluder compares with
    (salzman maps only dynamic casters once there are any)."""
    from pxr import Sdf

    st = _base()
    st.GetPrimAtPath("/World/Occluder").CreateAttribute("wsoft:dynamic", Sdf.ValueTypeNames.Bool).Set(True)
    return _save(st, folder, "base_dynamic")


def b_time_samples_only(folder):
    """The base with the light's and the occluder's translates authored only as time samples (at
    12, the base's places; at 24, elsewhere) and no time range."""
    from pxr import Gf, UsdGeom

    st = _base()
    (op,) = UsdGeom.Xformable(st.GetPrimAtPath("/World/Light")).GetOrderedXformOps()
    op.GetAttr().ClearDefault()
    op.Set(Gf.Vec3d(0, 0, 3), 12.0)
    op.Set(Gf.Vec3d(2, 0, 4), 24.0)
    occ = st.GetPrimAtPath("/World/Occluder")
    pts = occ.GetAttribute("points")
    pts.Set([Gf.Vec3f(p[0], p[1], 0.0) for p in pts.Get()])
    op = UsdGeom.Xformable(occ).AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 1), 12.0)
    op.Set(Gf.Vec3d(1, 0, 2), 24.0)
    return _save(st, folder, "time_samples_only")


# -- precision: far from the origin, a far light, a tiny scene, a lamp above a room's ceiling


def _moved(offset=(0.0, 0.0, 0.0), scale: float = 1.0, sphere_at: float | None = None):
    """The base moved by ``offset`` and scaled by ``scale`` (the camera's clipping range too);
    ``sphere_at``: a sphere light of the sun's angular radius (0.53°) at that height instead."""
    from wsoft.stages.builders import add_sphere_light

    st = make_stage()
    o = np.asarray(offset, np.float64)
    at = lambda p: tuple(o + scale * np.asarray(p, np.float64))  # noqa: E731
    add_quad(st, "/World/Ground", at((0, 0, 0)), 5 * scale)
    add_quad(st, "/World/Occluder", at((0, 0, 1)), 1 * scale)
    if sphere_at is None:
        add_rect_light(st, "/World/Light", at((0, 0, 3)), scale, scale)
    else:
        add_sphere_light(st, "/World/Light", at((0, 0, sphere_at)), scale * sphere_at * math.tan(math.radians(0.53)))
    add_camera(st, "/World/Cam", at((0, -6, 5)), at((0, 0, 0)), clip=(0.01 * scale, 1000.0 * scale))
    return st


def b_far_origin_xy(folder):
    """The base a million units from the origin in x and y (float32 spacing there: 0.06)."""
    return _save(_moved((1e6, 1e6, 0.0)), folder, "far_origin_xy")


def b_far_origin_z(folder):
    return _save(_moved((0.0, 0.0, 1e6)), folder, "far_origin_z")


def b_tiny_scene(folder):
    """The base a ten-billionth of its size."""
    return _save(_moved(scale=1e-10), folder, "tiny_scene")


def b_tiny_cutout(folder):
    """The base scaled by 1e-10 with cutout_8bit's checker occluder."""
    st = _moved(scale=1e-10)
    _cutout_occluder(st, _png(folder, "checker8.png", _checker(), "RGBA"))
    return _save(st, folder, "tiny_cutout")


def b_far_light_100(folder):
    """A sun-sized (0.53°) sphere light 100 units above the base's occluder."""
    return _save(_moved(sphere_at=100.0), folder, "far_light_100")


def b_far_light_1e4(folder):
    """The same angular size 10,000 units up: the same shadow."""
    return _save(_moved(sphere_at=1e4), folder, "far_light_1e4")


def b_room_ceiling(folder):
    """The base inside a closed, double-sided room (±2, z -0.5 to 2.5) whose ceiling lies half a
    unit below the rect light, the camera inside: everything it sees is in shadow."""
    from pxr import UsdGeom

    st = _base()
    st.RemovePrim("/World/Cam")
    room = add_box(st, "/World/Room", (-2, -2, -0.5), (2, 2, 2.5))
    UsdGeom.Mesh(room.GetPrim()).CreateDoubleSidedAttr(True)
    add_camera(st, "/World/Cam", (0, -1.5, 1), (0, 0, 0))
    return _save(st, folder, "room_ceiling")


# a sun whose cone a wall far outside the receivers' window partly blocks: 8 degrees wide, arriving from
# 30 degrees off the zenith on the -x side; the wall in the plane x = -100, 160 tall, its top edge seen
# from the ground at 56-59 degrees of elevation: inside the cone (56-64), above the light's centre (60)
SUN_WALL_ANGLE = 8.0
SUN_WALL_TOWARD = (-0.5, 0.0, math.sqrt(0.75))
SUN_WALL_X, SUN_WALL_HEIGHT = -100.0, 160.0


def _sun_wall(folder: str, name: str, half_width: float) -> str:
    """A ground (+-5) under an 8-degree sun, and a double-sided wall far off (x = -100, 160 tall,
    y within +-``half_width``) that blocks part of the sun's cone from every receiver but never its
    centre: the exact answer is a penumbra over the whole ground, V 0.6-0.96."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_sun(st, "/World/Light", SUN_WALL_ANGLE, toward=SUN_WALL_TOWARD)
    x, h, w = SUN_WALL_X, SUN_WALL_HEIGHT, half_width
    add_mesh(st, "/World/Wall", ([(x, -w, 0.0), (x, w, 0.0), (x, w, h), (x, -w, h)], [4], [0, 1, 2, 3]), True, minimal=True)
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return _save(st, folder, name)


def b_sun_far_wall(folder):
    """The wall 16 wide: its corners lie where a caster can block part of the sun's cone from a receiver."""
    return _sun_wall(folder, "sun_far_wall", 8.0)


def b_sun_huge_far_wall(folder):
    """The wall 2e4 wide: its corners lie far outside that region, its interior crosses it."""
    return _sun_wall(folder, "sun_huge_far_wall", 1e4)


# -- texture networks: the UsdPreviewSurface nodes between a cutout's texture and its mesh (wsoft.scene.usd_texture)


def _cut_node(st, name: str):
    from pxr import UsdShade

    return UsdShade.Shader(st.GetPrimAtPath(f"/World/Looks/Cut/{name}"))


def _clamped(st):
    from pxr import Sdf

    for nm in ("wrapS", "wrapT"):
        _cut_node(st, "Alpha").CreateInput(nm, Sdf.ValueTypeNames.Token).Set("clamp")


def b_cutout_clamp(folder):
    """The 8-bit checker cutout with wrapS = wrapT = clamp (what the scale/bias and UDIM cases equal)."""
    st = _base()
    _cutout_occluder(st, _png(folder, "checker8_clamp.png", _checker(), "RGBA"))
    _clamped(st)
    return _save(st, folder, "cutout_clamp")


def b_cutout_varname_uv(folder):
    """The checker cutout with its coordinates in a primvar ``uv`` (no ``st``), read by varname."""
    from pxr import Sdf, UsdGeom

    st = _base()
    _cutout_occluder(st, _png(folder, "checker8_uv.png", _checker(), "RGBA"))
    occ = UsdGeom.PrimvarsAPI(st.GetPrimAtPath("/World/Occluder"))
    occ.RemovePrimvar("st")
    occ.CreatePrimvar("uv", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    _cut_node(st, "St").GetInput("varname").Set("uv")
    return _save(st, folder, "cutout_varname_uv")


def b_cutout_transform2d(folder):
    """A UsdTransform2d (scale 0.5) between reader and texture, over a 16 x 16 texture holding the
    checker in its lower-left quarter (transparent elsewhere): the checker cutout, texel for texel."""
    from pxr import Sdf, UsdShade

    big = np.zeros((16, 16))
    big[8:, :8] = _checker()  # image rows run top-down: the lower-left quarter
    st = _base()
    _cutout_occluder(st, _png(folder, "checker16_quarter.png", big, "RGBA"))
    xf = UsdShade.Shader.Define(st, "/World/Looks/Cut/Transform")
    xf.CreateIdAttr("UsdTransform2d")
    xf.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(_cut_node(st, "St").ConnectableAPI(), "result")
    xf.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set((0.5, 0.5))
    _cut_node(st, "Alpha").GetInput("st").ConnectToSource(xf.ConnectableAPI(), "result")
    return _save(st, folder, "cutout_transform2d")


def b_cutout_scale_bias(folder):
    """The inverted checker read with scale -1, bias 1 on a (clamped): the clamped checker cutout."""
    from pxr import Sdf

    st = _base()
    _cutout_occluder(st, _png(folder, "checker8_inverted.png", 1 - _checker(), "RGBA"))
    _clamped(st)
    _cut_node(st, "Alpha").CreateInput("scale", Sdf.ValueTypeNames.Float4).Set((1.0, 1.0, 1.0, -1.0))
    _cut_node(st, "Alpha").CreateInput("bias", Sdf.ValueTypeNames.Float4).Set((0.0, 0.0, 0.0, 1.0))
    return _save(st, folder, "cutout_scale_bias")


def b_cutout_udim(folder):
    """``udim.<UDIM>.png`` with the occluder's st in tile 1002 ([1, 2] x [0, 1]): tile 1002 is the
    checker, tile 1001 opaque; the clamped checker cutout (UDIM tiles are clamped at their edges)."""
    from pxr import Sdf, UsdGeom

    _png(folder, "udim.1001.png", np.ones((8, 8)), "RGBA")
    _png(folder, "udim.1002.png", _checker(), "RGBA")
    st = _base()
    _cutout_occluder(st, "udim.<UDIM>.png")
    pv = UsdGeom.PrimvarsAPI(st.GetPrimAtPath("/World/Occluder")).GetPrimvar("st")
    pv.Set([(1, 0), (2, 0), (2, 1), (1, 1)])
    _cut_node(st, "Alpha").GetInput("file").Set(Sdf.AssetPath("udim.<UDIM>.png"))
    return _save(st, folder, "cutout_udim")


def b_cutout_exr(folder):
    """The checker as an OpenEXR texture (float32 RGBA): the 8-bit checker cutout."""
    import OpenEXR

    a = np.ascontiguousarray(_checker(), np.float32)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, {c: a for c in "RGBA"}) as f:
        f.write(os.path.join(folder, "checker.exr"))
    return _cutout_stage(folder, "cutout_exr", "checker.exr")


# -- light side and shape: a rect or disk light emits from its front only (its transformed local -Z)


def _turned_light(folder, name: str, op: str, value, disk: bool = False):
    """The base with its light (a DiskLight of radius 0.5 when ``disk``) turned away from every
    receiver by ``op`` (``rotate`` or ``scale``) ``value``: everything in view lies behind it."""
    from pxr import Gf, UsdGeom, UsdLux

    st = _base()
    if disk:
        st.RemovePrim("/World/Light")
        UsdLux.DiskLight.Define(st, "/World/Light").CreateRadiusAttr(0.5)
    xf = UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/Light"))
    xf.SetTranslate(Gf.Vec3d(0, 0, 3))
    (xf.SetRotate if op == "rotate" else xf.SetScale)(Gf.Vec3f(*value))
    return _save(st, folder, name)


def b_light_facing_away(folder):
    return _turned_light(folder, "light_facing_away", "rotate", (180, 0, 0))


def b_light_scaled_away(folder):
    return _turned_light(folder, "light_scaled_away", "scale", (1, 1, -1))


def b_light_inverted(folder):
    return _turned_light(folder, "light_inverted", "scale", (-1, -1, -1))


def b_disk_facing_away(folder):
    return _turned_light(folder, "disk_facing_away", "rotate", (0, 180, 0), disk=True)


# --------------------------------------------------------------------------- expectations


def _covered(ch):
    return ch["A"] > 0


def all_dark(ch, base=None, technique="") -> str | None:
    """Every covered pixel in shadow (filtered techniques may leak a little at the shade's rim)."""
    v = ch["V"][_covered(ch)]
    limit = 0.0 if technique in ("reference", "hard") else 0.03
    return None if v.size and v.mean() <= limit else f"mean V {v.mean():.3f} on covered pixels, want <= {limit}"


def all_lit(ch, base=None, technique="") -> str | None:
    """Nothing between the light and any covered pixel: V = 1 (a flat receiver square to the light
    alone in the map once made essm and vssm shadow themselves on 30% of the pixels)."""
    v = ch["V"][_covered(ch)]
    return None if v.size > 100 and v.min() >= 1.0 - 1e-6 else f"min V {v.min():.3f}, {int((v < 0.999).sum())} pixels below 1"


def _same_v(ch, other, what: str) -> str | None:
    """``other``'s V on the pixels both frames cover (more than 100 of them), to 1e-6."""
    both = _covered(ch) & (other["A"] > 0)
    d = np.abs(ch["V"] - other["V"])[both]
    return None if both.sum() > 100 and d.max() <= 1e-6 else f"V differs from {what} by up to {d.max():.3g} on {both.sum()} pixels"


def same_as_base(ch, base, technique="") -> str | None:
    """The base's V on the pixels both cover (out-of-view geometry must not move a shadow)."""
    return _same_v(ch, base, "the base")


def far_side_dark(ch, base=None, technique="") -> str | None:
    """Pixels whose normal turns away from the whole light (its top at z = 4, 1 x 1) are dark."""
    cov = _covered(ch)
    n = np.stack([ch["N.X"], ch["N.Y"], ch["N.Z"]], -1)
    p = np.stack([ch["P.X"], ch["P.Y"], ch["P.Z"]], -1)
    corners = np.array([[x, y, 4.0] for x in (-0.5, 0.5) for y in (-0.5, 0.5)])
    behind = np.all(np.einsum("hwi,khwi->khw", n, corners[:, None, None, :] - p[None]) < 0, axis=0) & cov
    front = np.all(np.einsum("hwi,khwi->khw", n, corners[:, None, None, :] - p[None]) > 0, axis=0) & cov & (ch["P.Z"] > 0.7)
    if behind.sum() < 20 or front.sum() < 5:
        return f"too few pixels to judge ({behind.sum()} behind, {front.sum()} lit top)"
    if ch["V"][behind].max() > 0:
        return f"{int((ch['V'][behind] > 0).sum())} pixels facing away from the light are lit"
    if ch["V"][front].min() < 0.99:
        return f"the lit top is shadowed (min V {ch['V'][front].min():.3f})"
    return None


# techniques whose V is the light's central direction's, filtered by a kernel of fixed width (no penumbra
# sized from the light: salzman's one blur width for every penumbra)
CENTRAL = ("hard", "pcf", "vsm", "esm", "evsm", "msm", "izb", "salzman")


def _sun_cone(n: int = 2048) -> np.ndarray:
    """``n`` unit directions toward the sun of :func:`_sun_wall`, evenly over its cone (a sunflower
    pattern over the disk of the cone's half-angle)."""
    c = np.asarray(SUN_WALL_TOWARD, np.float64)
    c /= np.linalg.norm(c)
    u = np.cross(c, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(c, u)
    k = np.arange(n) + 0.5
    rad = math.tan(math.radians(0.5 * SUN_WALL_ANGLE)) * np.sqrt(k / n)
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    d = c + rad[:, None] * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def sun_wall_penumbra(half_width: float):
    """A check of :func:`_sun_wall`'s stage with a wall of ``half_width``: the mean V over the ground
    within 0.1 of the exact visible fraction of the sun's cone past the wall (of the light's centre
    alone, never blocked, for the fixed-filter techniques of :data:`CENTRAL`). A map that misses the
    wall gives about 0.97 where the exact answer is about 0.8."""

    def check(ch, base=None, technique="") -> str | None:
        cov = _covered(ch) & (np.abs(ch["P.Z"]) < 1e-4)
        if cov.sum() < 100:
            return f"{int(cov.sum())} ground pixels"
        p = np.stack([ch["P.X"], ch["P.Y"], ch["P.Z"]], -1)[cov].astype(np.float64)
        c = np.asarray(SUN_WALL_TOWARD, np.float64)
        dirs = c[None] / np.linalg.norm(c) if technique in CENTRAL else _sun_cone()
        t = (SUN_WALL_X - p[:, None, 0]) / dirs[None, :, 0]  # along each direction to the wall's plane
        hy = p[:, None, 1] + t * dirs[None, :, 1]
        hz = p[:, None, 2] + t * dirs[None, :, 2]
        blocked = (t > 0) & (hz >= 0.0) & (hz <= SUN_WALL_HEIGHT) & (np.abs(hy) <= half_width)
        exact = 1.0 - blocked.mean(axis=1)
        got = ch["V"][cov].astype(np.float64)
        d = abs(got.mean() - exact.mean())
        return None if d <= 0.1 else f"mean V {got.mean():.3f} on {int(cov.sum())} ground pixels, the exact {exact.mean():.3f}"

    check.__doc__ = f"The sun's visible fraction past a wall {2 * half_width:g} wide, mean over the ground within 0.1."
    return check


def same_as(other: str):
    def check(ch, base, technique="", frames=None) -> str | None:
        return _same_v(ch, frames[other], other)

    check.__doc__ = f"The same V as the stage {other!r} on the same pixels."
    check.wants = other
    return check


def close_to(other: str, tol: float):
    """Mean |V - V_other| at most ``tol`` on the pixels both cover (a moved or rescaled copy of a
    stage: the same shadow up to float rounding and the reference's noise)."""

    def check(ch, base, technique="", frames=None) -> str | None:
        o = frames[other]
        both = _covered(ch) & (o["A"] > 0)
        either = int((_covered(ch) | (o["A"] > 0)).sum())
        if either - both.sum() > 0.01 * either:
            return f"covers {int(_covered(ch).sum())} pixels, {other} {int((o['A'] > 0).sum())} ({either - int(both.sum())} differ)"
        d = np.abs(ch["V"] - o["V"])[both]
        return None if both.sum() > 100 and d.mean() <= tol else f"mean |V - V({other})| {d.mean():.3g} on {both.sum()} pixels, want <= {tol:g}"

    check.__doc__ = f"Within {tol:g} of the stage {other!r} (mean over the pixels both cover)."
    check.wants = other
    return check


def ground_dark(ch, base=None, technique="") -> str | None:
    """The ground's top is dark (the light lies in or below its plane)."""
    g = _covered(ch) & (np.abs(ch["P.Z"]) < 1e-4)
    return None if g.sum() > 100 and ch["V"][g].max() == 0.0 else f"max V {ch['V'][g].max() if g.any() else -1:.3f} on {g.sum()} ground pixels"


@dataclass
class Case:
    """One case: its stage builder (folder -> stage path) and what every technique must give."""

    name: str
    build: Callable[[str], str]
    expect: str = "ok"  # ok | error
    message: tuple[str, ...] = ()  # substrings of the error line (error) or of some warning (ok)
    check: Callable | None = None
    base: str = "base"  # the stage 'same as base' compares with
    silent_hazard: bool = False  # an input that, left unchecked, gives a silent wrong answer or a traceback (marked in the report)
    warn_instead: bool = False  # a technique that misses the answer must say so in a warning with ``message``
    map_size: int = MAP  # texels (cells) per side of the techniques' light maps or grids (their size_param)
    note: str = ""


CASES: list[Case] = [
    Case("lamp_rect", b_lamp_rect, check=all_dark, silent_hazard=True, map_size=1024,
         note="rect light inside a closed box (lamp shade); 1024² maps (at 256² essm/vssm leak 0.09-0.10 at the shade's rim)"),
    Case("lamp_sphere", b_lamp_sphere, check=all_dark, silent_hazard=True, map_size=1024,
         note="sphere light inside a closed box: its receivers all around it, beyond a single frustum (a cube map); 1024² maps, as lamp_rect"),
    Case("huge_far_triangle", b_huge_far_triangle, check=same_as_base, silent_hazard=True, note="one triangle with corners at +-1e7, out of view"),
    Case("huge_far_triangle_sun", b_huge_far_triangle_sun, check=same_as_base, base="base_sun", silent_hazard=True,
         note="the same under a 2-degree sun"),
    Case("point_3e38", b_point_3e38, check=same_as_base, silent_hazard=True, note="a sliver triangle reaching 3e38"),
    Case("points_1e30", b_points_1e30, check=same_as_base, note="a triangle at 1e30"),
    Case("thin_plate_behind", b_thin_plate_behind, check=all_dark, silent_hazard=True, note="double-sided plate lit from behind"),
    Case("sphere", b_sphere, check=far_side_dark, silent_hazard=True, note="closed sphere: far side dark, top lit"),
    Case("light_on_receiver_plane", b_light_on_receiver_plane, note="light in the ground's plane (a boundary: no known answer)"),
    Case("light_below_ground", b_light_below_ground, check=ground_dark, note="light under a single-sided ground"),
    Case("mirrored", b_mirrored, check=same_as_base, note="occluder mirrored by a negative scale"),
    Case("zero_area", b_zero_area, check=same_as_base, note="degenerate triangles"),
    Case("camera_inside", b_camera_inside, note="camera inside a closed box"),
    Case("usdc", b_usdc, check=same_as_base, note="the base as .usdc"),
    Case("no_occluder", b_no_occluder, check=all_lit, note="the base without its occluder: all lit"),
    Case("cutout_8bit", b_cutout_8bit, note="8-bit RGBA cutout texture"),
    Case("cutout_16bit", b_cutout_16bit, check=same_as("cutout_8bit"), note="16-bit grey cutout texture (opacity from r)"),
    Case("cutout_palette", b_cutout_palette, check=same_as("cutout_8bit"), note="palette PNG cutout texture"),
    Case("cutout_1x1", b_cutout_1x1, check=same_as("no_occluder"), note="1x1 transparent texture: no occluder left"),
    Case("cutout_usdz", b_cutout_usdz, check=same_as("cutout_8bit"), silent_hazard=True, note="cutout texture inside a .usdz"),
    Case("cutout_truncated_png", b_cutout_truncated_png, message=("cannot be read",), note="truncated PNG: warned, opaque"),
    Case("zero_width_rect", b_zero_width_rect, message=("zero width",), note="RectLight of width 0"),
    Case("inverted_clip", b_inverted_clip, message=("clippingRange",), note="camera clipping range inverted"),
    Case("missing_sublayer", b_missing_sublayer, message=("not_there.usda",), note="a sublayer that is not there"),
    Case("missing_reference", b_missing_reference, message=("no_such_asset.usda",), note="a reference that is not there"),
    Case("rect_nan_width", b_rect_nan_width, "error", ("/World/Light", "inputs:width"), silent_hazard=True),
    Case("rect_inf_width", b_rect_inf_width, "error", ("/World/Light", "inputs:width"), silent_hazard=True),
    Case("sphere_nan_radius", b_sphere_nan_radius, "error", ("/World/Light", "inputs:radius"), silent_hazard=True),
    Case("disk_inf_radius", b_disk_inf_radius, "error", ("/World/Light", "inputs:radius"), silent_hazard=True),
    Case("disk_negative_radius", b_disk_negative_radius, "error", ("/World/Light", "inputs:radius"), silent_hazard=True),
    Case("exposure_huge", b_exposure_huge, "error", ("/World/Light", "exposure"), silent_hazard=True, note="exposure 1e6: 2^exposure overflows a float"),
    Case("nan_transform", b_nan_transform, "error", ("/World/Occluder", "transform"), silent_hazard=True),
    Case("inf_transform", b_inf_transform, "error", ("/World/Occluder",), silent_hazard=True),
    Case("negative_count", b_negative_count, "error", ("/World/Occluder", "faceVertexCounts"), silent_hazard=True),
    Case("count_5_minus_2", b_count_5_minus_2, "error", ("/World/Occluder", "faceVertexCounts"), silent_hazard=True,
         note="face counts 5 and -2: their sum matches the 3 indices"),
    Case("broken_syntax", b_broken_syntax, "error", ("broken_syntax.usda:5:3", "parse error")),
    Case("empty", b_empty, "error", ("no shadow-casting light",)),
    Case("dome_only", b_dome_only, "error", ("/World/Dome",)),
    # -- mesh topology and time samples (holeIndices, concave faces, samples without a time range)
    Case("hole_face", b_hole_face, check=all_lit, silent_hazard=True, note="the occluder's only face is a hole (holeIndices): nothing casts"),
    Case("concave_pentagon_split", b_concave_pentagon_split, note="a concave pentagon occluder authored as the three triangles that split it"),
    Case("concave_pentagon", b_concave_pentagon, check=same_as("concave_pentagon_split"), silent_hazard=True,
         note="the same pentagon as one face (its first corner does not see all of it: not a fan)"),
    Case("time_samples_only", b_time_samples_only, message=("loaded at time code 12",), check=same_as_base, base="base_dynamic",
         silent_hazard=True, note="light and occluder translates only time-sampled, no time range: the earliest sample"),
    # precision
    Case("far_origin_xy", b_far_origin_xy, check=close_to("base", 0.005), silent_hazard=True,
         note="the base 1e6 from the origin in x and y"),
    Case("far_origin_z", b_far_origin_z, check=close_to("base", 0.005), silent_hazard=True, note="the base 1e6 up in z"),
    Case("tiny_scene", b_tiny_scene, check=close_to("base", 0.005), silent_hazard=True, note="the base scaled by 1e-10"),
    Case("tiny_cutout", b_tiny_cutout, check=close_to("cutout_8bit", 0.005), silent_hazard=True,
         note="cutout_8bit scaled by 1e-10 (the step past a cutout's hole is relative)"),
    Case("far_light_1e4", b_far_light_1e4, check=close_to("far_light_100", 0.006), silent_hazard=True,
         note="a 0.53° sphere light 1e4 up: the shadow it casts from 100 up"),
    Case("room_ceiling", b_room_ceiling, check=all_dark, silent_hazard=True,
         note="camera inside a closed double-sided room, the lamp half a unit above its ceiling"),
    Case("sun_far_wall", b_sun_far_wall, check=sun_wall_penumbra(8.0), silent_hazard=True,
         note="an 8-degree sun partly blocked by a wall 100 away, outside the receivers' window: a penumbra over the whole ground"),
    Case("sun_huge_far_wall", b_sun_huge_far_wall, check=sun_wall_penumbra(1e4), silent_hazard=True,
         note="the same wall 2e4 wide: its corners far outside the region where a caster can shadow a receiver"),
    # texture networks: the UsdPreviewSurface nodes between a cutout's texture and its mesh
    Case("cutout_clamp", b_cutout_clamp, note="8-bit cutout texture, wrapS = wrapT = clamp"),
    Case("cutout_varname_uv", b_cutout_varname_uv, check=same_as("cutout_8bit"), silent_hazard=True,
         note="texture coordinates in primvar uv, read by varname (no st)"),
    Case("cutout_transform2d", b_cutout_transform2d, check=same_as("cutout_8bit"), silent_hazard=True,
         note="UsdTransform2d (scale 0.5) onto the lower-left quarter of a 16x16 texture"),
    Case("cutout_scale_bias", b_cutout_scale_bias, check=same_as("cutout_clamp"), silent_hazard=True,
         note="inverted texture read with scale -1, bias 1"),
    Case("cutout_udim", b_cutout_udim, check=same_as("cutout_clamp"), silent_hazard=True, note="UDIM texture, st in tile 1002"),
    Case("cutout_exr", b_cutout_exr, check=same_as("cutout_8bit"), silent_hazard=True, note="OpenEXR cutout texture"),
    # light side and shape
    Case("light_facing_away", b_light_facing_away, check=all_dark, message=("behind its emitting plane",), silent_hazard=True,
         note="the base's rect light turned 180 degrees about X: it emits up, away from everything"),
    Case("light_scaled_away", b_light_scaled_away, check=all_dark, message=("behind its emitting plane",), silent_hazard=True,
         note="the base's rect light scaled (1, 1, -1): its -Z turned up"),
    Case("light_inverted", b_light_inverted, check=all_dark, message=("behind its emitting plane",), silent_hazard=True,
         note="the base's rect light scaled (-1, -1, -1): its -Z turned up"),
    Case("disk_facing_away", b_disk_facing_away, check=all_dark, message=("behind its emitting plane",), silent_hazard=True,
         note="a DiskLight in the base's light's place, turned 180 degrees about Y"),
]
BASES = {"base": b_base, "base_sun": b_base_sun, "base_dynamic": b_base_dynamic, "far_light_100": b_far_light_100}


@dataclass
class Result:
    """What a case gave through the command line: exit code, its one error line, the warnings,
    the frame's stats and channels (exit 0), everything it wrote to stderr."""

    rc: int
    error: str = ""  # the one error line (exit 2)
    warnings: list[str] = field(default_factory=list)
    stats: dict | None = None
    channels: dict | None = None
    stderr: str = ""


def judge(case: Case, technique: str, res: Result, frame_of: Callable[[str], dict | None]) -> list[str]:
    """What is wrong with a result (empty: as expected); ``frame_of(stage name)`` gives the channels
    of another stage rendered with the same technique (the base, or the one a case must equal)."""
    problems = []
    if case.expect == "error":
        if res.rc != 2:
            problems.append(f"exit {res.rc}, want 2")
        if "\n" in res.error or not res.error:
            problems.append("no one-line error")
        problems += [f"error line lacks {m!r}: {res.error}" for m in case.message if m not in res.error]
        if "Traceback" in res.stderr:
            problems.append("traceback")
        return problems
    if res.rc != 0:
        return [f"exit {res.rc}: {res.error or res.stderr.strip()[-300:]}"]
    if res.stats.get("nonfinite"):
        problems.append(f"non-finite values: {res.stats['nonfinite']}")
    warned = all(any(m in w for w in res.warnings) for m in case.message)
    if not case.warn_instead and not warned:
        problems += [f"no warning with {m!r}" for m in case.message if not any(m in w for w in res.warnings)]
    if "Traceback" in res.stderr or "Warning: in " in res.stderr:
        problems.append("raw USD or Python diagnostics on stderr")
    if case.check is not None:
        wants = getattr(case.check, "wants", None)
        if wants is not None:
            other = frame_of(wants)
            msg = case.check(res.channels, None, technique, {wants: other}) if other is not None else f"no frame of {wants}"
        else:
            msg = case.check(res.channels, frame_of(case.base), technique)
        if msg and not (case.warn_instead and warned):
            problems.append(msg + (f" and no warning with {case.message}" if case.warn_instead else ""))
    return problems


# known defects the corpus shows: (case, technique) -> what the defect is and where it lies
KNOWN: dict[tuple[str, str], str] = {
}


@contextlib.contextmanager
def _quiet_usd():
    """Keep USD's own warnings (a builder authoring a missing sublayer) off stderr."""
    from pxr import UsdUtils

    d = UsdUtils.CoalescingDiagnosticDelegate()
    try:
        yield
    finally:
        d.TakeUncoalescedDiagnostics()
        del d


def write_stage(name: str, folder: str) -> str:
    """Write the stage of case (or base) ``name`` into ``folder``; its path. USD's own diagnostics
    while building (a missing sublayer authored on purpose) are kept off stderr."""
    build = BASES.get(name) or next(c.build for c in CASES if c.name == name)
    with _quiet_usd():
        return build(folder)
