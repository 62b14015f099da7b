"""The corpus's stages of geometry, lights and transforms: lamps, far and huge triangles, degenerate
and broken meshes, bad light attributes, time samples, precision far from the origin."""

from __future__ import annotations

import contextlib
import math
import os

import numpy as np

from wsoft.stages.builders import add_box, add_camera, add_mesh, add_quad, add_rect_light, make_stage

from wsoft.stages.adversarial.common import _base, _checker, _cutout_occluder, _png, _save, _sphere_mesh, _triangle

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
