"""The known failure cases of the filtered techniques as in-memory stages: the tests pin them and
the ``filtered`` sweep shows them (technique, reference, difference)."""

from __future__ import annotations


def _stage():
    from pxr import Usd, UsdGeom

    st = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(st, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(st, 1.0)
    UsdGeom.Xform.Define(st, "/World")
    return st


def quad(st, path, center, half, dynamic=False):
    from pxr import Sdf, UsdGeom

    cx, cy, cz = center
    m = UsdGeom.Mesh.Define(st, path)
    m.CreatePointsAttr([(cx - half, cy - half, cz), (cx + half, cy - half, cz), (cx + half, cy + half, cz), (cx - half, cy + half, cz)])
    m.CreateFaceVertexCountsAttr([4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    m.CreateDoubleSidedAttr(True)
    if dynamic:
        m.GetPrim().CreateAttribute("wsoft:dynamic", Sdf.ValueTypeNames.Bool).Set(True)
    return m


def box(st, path, lo, hi):
    from pxr import UsdGeom

    m = UsdGeom.Mesh.Define(st, path)
    p = [(x, y, z) for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    m.CreatePointsAttr(p)
    m.CreateFaceVertexCountsAttr([4] * 6)
    m.CreateFaceVertexIndicesAttr([i for q in quads for i in q])
    return m


def rect_light(st, path, pos, w, h):
    from pxr import Gf, UsdGeom, UsdLux

    light = UsdLux.RectLight.Define(st, path)
    light.CreateWidthAttr(w)
    light.CreateHeightAttr(h)
    UsdGeom.XformCommonAPI(light).SetTranslate(Gf.Vec3d(*pos))
    return light


def camera(st, path, eye, target, up=(0, 0, 1), focal=18.0):
    from pxr import Gf, UsdGeom

    cam = UsdGeom.Camera.Define(st, path)
    cam.AddTransformOp().Set(Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*target), Gf.Vec3d(*up)).GetInverse())
    cam.CreateFocalLengthAttr(focal)
    cam.CreateHorizontalApertureAttr(20.955)
    cam.CreateVerticalApertureAttr(20.955)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 1000))
    return cam


def pcss_overlapping_blockers(high: bool = True):
    """Blockers at two depths average to one too near the light: the filter grows into the umbra."""
    st = _stage()
    quad(st, "/World/G", (0, 0, 0), 6)
    quad(st, "/World/Low", (0, 0, 0.6), 1.5)  # large, close to the ground: a wide umbra
    if high:
        quad(st, "/World/High", (0.2, 0, 3.0), 0.2)  # small, near the light, inside the blocker search
    rect_light(st, "/World/L", (0, 0, 4), 1.0, 1.0)
    camera(st, "/World/Cam", (0, -5, 0.35), (0, 0, 0), focal=16)  # low, to see the ground under Low
    return st


def vsm_stacked_occluders(upper: bool = True):
    """An upper occluder's edge over a lower one's umbra: the moments' variance lets light bleed in."""
    st = _stage()
    quad(st, "/World/G", (0, 0, 0), 6)
    quad(st, "/World/Lower", (0, 0, 0.5), 1.5)
    if upper:
        quad(st, "/World/Upper", (-0.8, 0, 2.5), 0.8)  # its edge at x = 0, over Lower's umbra
    rect_light(st, "/World/L", (0, 0, 4), 0.3, 0.3)
    camera(st, "/World/Cam", (0, -5, 0.3), (0, 0, 0.1), focal=16)  # low: sees under Lower
    return st


def esm_contact():
    """A thin plate just above the ground under a slanted sun: the receiver is only a little
    behind the occluder, so exp(-c (z - d)) stays above 0 and light leaks in."""
    from pxr import Gf, UsdGeom, UsdLux

    st = _stage()
    quad(st, "/World/G", (0, 0, 0), 4)
    box(st, "/World/Plate", (-1.0, -1.0, 0.1), (1.0, 1.0, 0.13))
    sun = UsdLux.DistantLight.Define(st, "/World/Sun")
    sun.CreateAngleAttr(0.5)
    UsdGeom.XformCommonAPI(sun).SetRotate(Gf.Vec3f(0, -45, 0))
    camera(st, "/World/Cam", (1, -3, 3), (0.3, 0, 0), focal=18)
    return st


def salzman_receiver_between_casters(lower: bool = True):
    """A shelf between two dynamic casters: near the upper caster's edge the blur averages the two
    casters' depths, the reconstructed depth falls behind the shelf and the shelf escapes."""
    from pxr import Gf, UsdGeom, UsdLux

    st = _stage()
    quad(st, "/World/Ground", (0, 0, 0), 5)
    shelf = UsdGeom.Mesh.Define(st, "/World/Shelf")  # a narrow strip: the ground stays in view
    shelf.CreatePointsAttr([(-1.5, -0.1, 2.0), (1.5, -0.1, 2.0), (1.5, 0.1, 2.0), (-1.5, 0.1, 2.0)])
    shelf.CreateFaceVertexCountsAttr([4])
    shelf.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    shelf.CreateDoubleSidedAttr(True)
    quad(st, "/World/Upper", (0.3, 0, 2.6), 0.6, dynamic=True)
    if lower:
        quad(st, "/World/Lower", (0, 0, 0.1), 1.2, dynamic=True)
    bulb = UsdLux.SphereLight.Define(st, "/World/L")  # a point light: the umbra reaches the caster's edge
    bulb.CreateTreatAsPointAttr(True)
    UsdGeom.XformCommonAPI(bulb).SetTranslate(Gf.Vec3d(0, 0, 4))
    camera(st, "/World/Cam", (-0.45, -0.001, 3.3), (-0.45, 0, 2.0), focal=50)  # at the upper caster's edge
    return st


# name -> (stage builder, technique, its parameters, reference parameters)
FAILURES = {
    "pcss_overlapping_blockers": (pcss_overlapping_blockers, "pcss", {}, {"samples": 256}),
    "vsm_stacked_occluders": (vsm_stacked_occluders, "vsm", {"radius": 4, "bleed_reduction": 0.0}, {"samples": 64}),
    "esm_contact": (esm_contact, "esm", {"c": 20.0}, {"samples": 64}),
    "salzman_receiver_between_casters": (salzman_receiver_between_casters, "salzman", {"radius": 16, "shadow_map_size": 512}, {"samples": 1, "casters": "dynamic"}),
}
