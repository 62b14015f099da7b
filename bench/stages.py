"""In-memory USD stages, built the same way by the tests and the benchmark sweeps (one copy).

Every builder takes the stage first and returns the prim schema it defined; stages are Z-up with
``metersPerUnit = 1`` and an Xform ``/World`` unless asked otherwise.
"""

from __future__ import annotations


def make_stage(up: str = "Z"):
    """An in-memory stage with its up axis and a ``/World`` Xform."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "Z" else UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Xform.Define(stage, "/World")
    return stage


def add_quad(stage, path: str, center, half: float, *, normal_axis: str = "z", double_sided: bool = True, st: bool = False,
             dynamic: bool = False):
    """A square of half-side ``half`` in the plane perpendicular to ``normal_axis`` (z: the XY
    plane), counter-clockwise seen from +axis; ``st``: texture coordinates (0..1 over it);
    ``dynamic``: marked ``wsoft:dynamic = true``."""
    from pxr import Sdf, UsdGeom

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
    if dynamic:
        mesh.GetPrim().CreateAttribute("wsoft:dynamic", Sdf.ValueTypeNames.Bool).Set(True)
    return mesh


def add_box(stage, path: str, lo, hi):
    """A closed, outward-wound box between the corners ``lo`` and ``hi``."""
    from pxr import UsdGeom

    m = UsdGeom.Mesh.Define(stage, path)
    p = [(x, y, z) for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    m.CreatePointsAttr(p)
    m.CreateFaceVertexCountsAttr([4] * 6)
    m.CreateFaceVertexIndicesAttr([i for q in quads for i in q])
    return m


def add_rect_light(stage, path: str, pos, w: float, h: float, shadow=None):
    """A RectLight of ``w x h`` at ``pos`` facing down its −Z; ``shadow``: author ``inputs:shadow:enable``."""
    from pxr import Gf, UsdGeom, UsdLux

    light = UsdLux.RectLight.Define(stage, path)
    light.CreateWidthAttr(w)
    light.CreateHeightAttr(h)
    UsdGeom.XformCommonAPI(light).SetTranslate(Gf.Vec3d(*pos))
    if shadow is not None:
        UsdLux.ShadowAPI.Apply(light.GetPrim()).CreateShadowEnableAttr(shadow)
    return light


def add_point_light(stage, path: str, pos):
    """A SphereLight treated as a point."""
    from pxr import Gf, UsdGeom, UsdLux

    light = UsdLux.SphereLight.Define(stage, path)
    light.CreateTreatAsPointAttr(True)
    UsdGeom.XformCommonAPI(light).SetTranslate(Gf.Vec3d(*pos))
    return light


def add_sun(stage, path: str, angle: float, rotate=(0.0, -45.0, 0.0)):
    """A DistantLight of full cone angle ``angle`` (degrees), rotated by ``rotate`` (XYZ degrees)."""
    from pxr import Gf, UsdGeom, UsdLux

    sun = UsdLux.DistantLight.Define(stage, path)
    sun.CreateAngleAttr(angle)
    UsdGeom.XformCommonAPI(sun).SetRotate(Gf.Vec3f(*rotate))
    return sun


def add_camera(stage, path: str, eye, target, up=(0, 0, 1), focal: float = 18.0):
    """A perspective camera at ``eye`` looking at ``target`` (square 20.955 mm apertures)."""
    from pxr import Gf, UsdGeom

    cam = UsdGeom.Camera.Define(stage, path)
    cam.AddTransformOp().Set(Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*target), Gf.Vec3d(*up)).GetInverse())
    cam.CreateFocalLengthAttr(focal)
    cam.CreateHorizontalApertureAttr(20.955)
    cam.CreateVerticalApertureAttr(20.955)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 1000))
    return cam
