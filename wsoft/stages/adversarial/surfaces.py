"""The corpus's stages of a sun blocked far off, cutout texture networks and lights facing away."""

from __future__ import annotations

import math
import os

import numpy as np

from wsoft.stages.builders import add_camera, add_mesh, add_quad, add_sun, make_stage

from wsoft.stages.adversarial.common import _base, _checker, _cutout_occluder, _png, _save
from wsoft.stages.adversarial.geometry import _cutout_stage

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
