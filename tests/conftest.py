"""Shared fixtures: in-memory stages, devices, small render sizes."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "usd_scenes")
sys.path.insert(0, ROOT)


def _devices():
    import warp as wp

    import wsoft.parallel  # noqa: F401

    wp.init()
    devs = ["cpu"]
    if wp.is_cuda_available():
        devs.append("cuda:0")
    return devs


DEVICES = _devices()


@pytest.fixture(params=DEVICES)
def device(request):
    return request.param


def scene_path(name: str) -> str:
    return os.path.join(SCENES, name)


def make_stage(up: str = "Z"):
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "Z" else UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Xform.Define(stage, "/World")
    return stage


def add_quad(stage, path: str, center, half: float, *, normal_axis: str = "z", double_sided: bool = True, st: bool = False):
    """A square in the plane perpendicular to ``normal_axis`` (z: XY plane), counter-clockwise from +axis."""
    from pxr import UsdGeom, Sdf

    cx, cy, cz = center
    if normal_axis == "z":
        pts = [(cx - half, cy - half, cz), (cx + half, cy - half, cz), (cx + half, cy + half, cz), (cx - half, cy + half, cz)]
    else:  # y
        pts = [(cx - half, cy, cz - half), (cx - half, cy, cz + half), (cx + half, cy, cz + half), (cx + half, cy, cz - half)]
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(pts)
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    mesh.CreateDoubleSidedAttr(double_sided)
    if st:
        pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
        pv.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    return mesh


def add_rect_light(stage, path: str, pos, w: float, h: float, shadow=None):
    from pxr import Gf, UsdGeom, UsdLux

    light = UsdLux.RectLight.Define(stage, path)
    light.CreateWidthAttr(w)
    light.CreateHeightAttr(h)
    UsdGeom.XformCommonAPI(light).SetTranslate(Gf.Vec3d(*pos))
    if shadow is not None:
        UsdLux.ShadowAPI.Apply(light.GetPrim()).CreateShadowEnableAttr(shadow)
    return light


def add_camera(stage, path: str, eye, target, up=(0, 0, 1), focal=18.0):
    from pxr import Gf, UsdGeom

    cam = UsdGeom.Camera.Define(stage, path)
    m = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*target), Gf.Vec3d(*up)).GetInverse()
    cam.AddTransformOp().Set(m)
    cam.CreateFocalLengthAttr(focal)
    cam.CreateHorizontalApertureAttr(20.955)
    cam.CreateVerticalApertureAttr(20.955)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 1000))
    return cam


def parallel_rect_exact(px, py, light_z, occ_z, occ_half, light_half):
    """Exact visible fraction of a square light (side 2*light_half at height light_z, centred on the
    z axis) seen from ground points (px, py, 0) past a square occluder (side 2*occ_half at occ_z).

    The occluder projects from each ground point onto the light plane as a square scaled by
    light_z / occ_z about the point; the covered part of the light is the overlap of two
    axis-aligned squares, so the answer is a product of 1-D overlaps.
    """
    s = light_z / occ_z

    def overlap(p):
        lo = p + (-occ_half - p) * s
        hi = p + (occ_half - p) * s
        a, b = np.maximum(lo, -light_half), np.minimum(hi, light_half)
        return np.clip(b - a, 0, None) / (2 * light_half)

    return 1.0 - overlap(np.asarray(px)) * overlap(np.asarray(py))


def box_plane_ground_error(f, min_penumbra: int = 100):
    """Error of a render of ``box_plane.usda`` on its ground against :func:`parallel_rect_exact`:
    (MAE, MAE in the exact penumbra, max). Asserts the view holds at least ``min_penumbra``
    penumbra pixels, so a test cannot pass on an empty penumbra."""
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    exact = parallel_rect_exact(f["P.X"], f["P.Y"], 3.0, 1.0, 1.0, 0.5)
    err = np.abs(f.V - exact)[g]
    pen = ((exact > 0.01) & (exact < 0.99))[g]
    assert pen.sum() > min_penumbra
    return err.mean(), err[pen].mean(), err.max()
