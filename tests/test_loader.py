"""Scene loading from in-memory stages: axes, n-gons, winding, instancing, materials, lights."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import add_camera, add_quad, add_rect_light, make_stage

import wsoft
from wsoft.errors import SceneError
from wsoft.scene.types import LIGHT_DISK, LIGHT_DISTANT, LIGHT_POINT, LIGHT_RECT, LIGHT_SPHERE


def tri_normals(scene):
    p = scene.points[scene.triangles]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def test_up_axis_and_units():
    for up in ("Y", "Z"):
        st = make_stage(up)
        add_quad(st, "/World/Q", (0, 0, 0), 1)
        add_rect_light(st, "/World/L", (0, 0, 3), 1, 1)
        s = wsoft.load_scene(st)
        assert s.up_axis == up
        assert s.meters_per_unit == 1.0


def test_ngon_triangulation_area():
    from pxr import UsdGeom

    st = make_stage()
    m = UsdGeom.Mesh.Define(st, "/World/Hex")
    ang = np.linspace(0, 2 * np.pi, 7)[:-1]
    m.CreatePointsAttr([(float(np.cos(a)), float(np.sin(a)), 0.0) for a in ang])
    m.CreateFaceVertexCountsAttr([6])
    m.CreateFaceVertexIndicesAttr(list(range(6)))
    s = wsoft.load_scene(st)
    assert s.triangle_count == 4
    area = 0.5 * np.linalg.norm(tri_normals(s), axis=1).sum()
    assert area == pytest.approx(3 * np.sqrt(3) / 2, rel=1e-5)
    assert np.all(tri_normals(s)[:, 2] > 0)  # counter-clockwise from +Z stays facing +Z


def test_left_handed_flips_winding():
    st = make_stage()
    add_quad(st, "/World/R", (0, 0, 0), 1)
    q = add_quad(st, "/World/L", (5, 0, 0), 1)
    q.CreateOrientationAttr("leftHanded")
    s = wsoft.load_scene(st)
    n = tri_normals(s)
    right = s.tri_prim == s.prims.index("/World/R")
    assert np.all(n[right][:, 2] > 0) and np.all(n[~right][:, 2] < 0)


def test_mirroring_transform_keeps_facing():
    from pxr import Gf, UsdGeom

    st = make_stage()
    q = add_quad(st, "/World/Q", (0, 0, 0), 1)
    UsdGeom.XformCommonAPI(q).SetScale(Gf.Vec3f(-1, 1, 1))
    s = wsoft.load_scene(st)
    assert np.all(tri_normals(s)[:, 2] > 0)


def test_instancing_through_instance_proxies():
    from pxr import Gf, UsdGeom

    st = make_stage()
    proto = st.CreateClassPrim("/Protos")
    add_quad(st, "/Protos/Tile/Q", (0, 0, 0), 0.5)
    for i, x in enumerate((0.0, 3.0, 6.0)):
        inst = UsdGeom.Xform.Define(st, f"/World/Inst{i}")
        inst.GetPrim().GetReferences().AddInternalReference("/Protos/Tile")
        inst.GetPrim().SetInstanceable(True)
        UsdGeom.XformCommonAPI(inst).SetTranslate(Gf.Vec3d(x, 0, 0))
    assert proto
    s = wsoft.load_scene(st)
    assert s.triangle_count == 6
    xs = sorted(round(float(s.points[s.triangles[s.tri_prim == i]].reshape(-1, 3).mean(axis=0)[0]), 3) for i in range(len(s.prims)))
    assert xs == [0.0, 3.0, 6.0]


def test_invisible_and_guide_prims_skipped():
    from pxr import UsdGeom

    st = make_stage()
    add_quad(st, "/World/Seen", (0, 0, 0), 1)
    add_quad(st, "/World/Hidden", (3, 0, 0), 1).CreateVisibilityAttr("invisible")
    add_quad(st, "/World/Guide", (6, 0, 0), 1).CreatePurposeAttr(UsdGeom.Tokens.guide)
    add_quad(st, "/World/Proxy", (9, 0, 0), 1).CreatePurposeAttr(UsdGeom.Tokens.proxy)
    s = wsoft.load_scene(st)
    assert s.prims == ["/World/Seen"]


def _texture(tmp_path, name="alpha.png", pattern="checker", n=8, size=64):
    from PIL import Image

    yy, xx = np.mgrid[0:size, 0:size] * n // size
    if pattern == "checker":
        a = ((xx + yy) % 2 == 0)
    elif pattern == "quarter":  # opaque where both cell indices are even: 1/4 opaque
        a = (xx % 2 == 0) & (yy % 2 == 0)
    else:  # top half of the image opaque
        a = np.mgrid[0:size, 0:size][0] < size // 2
    rgba = np.zeros((size, size, 4), np.uint8)
    rgba[..., 0] = 200
    rgba[..., 3] = np.where(a, 255, 0)
    path = tmp_path / name
    Image.fromarray(rgba, "RGBA").save(path)
    return str(path)


def add_cutout_material(stage, mesh, tex_file: str, path="/World/Looks/Cut", threshold=0.5, wrap="repeat"):
    from pxr import Sdf, UsdShade

    mat = UsdShade.Material.Define(stage, path)
    sh = UsdShade.Shader.Define(stage, path + "/Surface")
    sh.CreateIdAttr("UsdPreviewSurface")
    tex = UsdShade.Shader.Define(stage, path + "/Tex")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(tex_file)
    tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(wrap)
    tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(wrap)
    reader = UsdShade.Shader.Define(stage, path + "/St")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    alpha_out = tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
    sh.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(alpha_out)
    sh.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(threshold)
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    return mat


def test_cutout_material_and_texture_orientation(tmp_path):
    st = make_stage()
    q = add_quad(st, "/World/Fence", (0, 0, 1), 1, st=True)
    add_cutout_material(st, q, _texture(tmp_path, pattern="top"))
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    s = wsoft.load_scene(st)
    assert s.has_cutouts
    assert s.cutout_triangle_counts() == {"/World/Looks/Cut": 2}
    tex = s.textures[0]
    # image top half opaque -> st.t near 1 (row 0 after flipping is the image's bottom) is opaque
    assert tex.data[-1, 0] == 1.0 and tex.data[0, 0] == 0.0
    fence = s.tri_prim == s.prims.index("/World/Fence")
    assert np.allclose(s.tri_uv[fence].reshape(-1, 2).min(axis=0), 0) and np.allclose(s.tri_uv[fence].reshape(-1, 2).max(axis=0), 1)


def test_face_varying_indexed_st_and_geomsubset_binding(tmp_path):
    from pxr import Sdf, UsdGeom, UsdShade, Vt

    st = make_stage()
    m = UsdGeom.Mesh.Define(st, "/World/Two")
    m.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0)])
    m.CreateFaceVertexCountsAttr([4, 4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3, 1, 4, 5, 2])
    pv = UsdGeom.PrimvarsAPI(m).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    pv.Set(Vt.Vec2fArray([(0, 0), (1, 0), (1, 1), (0, 1)]))
    pv.SetIndices(Vt.IntArray([0, 1, 2, 3, 0, 1, 2, 3]))
    subset = UsdGeom.Subset.CreateGeomSubset(m, "right", UsdGeom.Tokens.face, Vt.IntArray([1]), "materialBind")
    add_cutout_material(st, subset, _texture(tmp_path))
    plain = UsdShade.Material.Define(st, "/World/Looks/Plain")
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(plain)
    s = wsoft.load_scene(st)
    assert s.triangle_count == 4
    cut = [s.materials[i].is_cutout for i in s.tri_material]
    assert cut == [False, False, True, True]
    assert np.allclose(s.tri_uv[2], [(0, 0), (1, 0), (1, 1)])


def test_missing_texture_is_a_warning_and_opaque(tmp_path):
    st = make_stage()
    q = add_quad(st, "/World/Fence", (0, 0, 1), 1, st=True)
    add_cutout_material(st, q, str(tmp_path / "nope.png"))
    s = wsoft.load_scene(st)
    assert not s.has_cutouts
    assert any("nope.png" in w and "not found" in w for w in s.warnings)


def test_each_light_kind_and_shadow_disable():
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 5)
    add_rect_light(st, "/World/Rect", (0, 0, 3), 2.0, 1.0)
    d = UsdLux.DiskLight.Define(st, "/World/Disk")
    d.CreateRadiusAttr(0.25)
    sp = UsdLux.SphereLight.Define(st, "/World/Sphere")
    sp.CreateRadiusAttr(0.5)
    UsdGeom.XformCommonAPI(sp).SetTranslate(Gf.Vec3d(1, 1, 4))
    pt = UsdLux.SphereLight.Define(st, "/World/Point")
    pt.CreateTreatAsPointAttr(True)
    sun = UsdLux.DistantLight.Define(st, "/World/Sun")
    sun.CreateAngleAttr(4.0)
    off = add_rect_light(st, "/World/Off", (0, 0, 5), 1, 1, shadow=False)
    UsdLux.PortalLight.Define(st, "/World/Portal")
    assert off
    s = wsoft.load_scene(st)
    kinds = {l.name: l.kind for l in s.lights}
    assert kinds == {"Rect": LIGHT_RECT, "Disk": LIGHT_DISK, "Sphere": LIGHT_SPHERE, "Point": LIGHT_POINT, "Sun": LIGHT_DISTANT}
    rect = s.find_light("Rect")
    assert rect.half_size == pytest.approx((1.0, 0.5))
    assert np.allclose(rect.direction, [0, 0, -1])
    assert s.find_light("Disk").radius == pytest.approx(0.25)
    assert s.find_light("Sphere").radius == pytest.approx(0.5)
    assert np.allclose(s.find_light("Sphere").position, [1, 1, 4])
    assert s.find_light("Sun").angle_deg == pytest.approx(4.0)
    assert [l.path for l in s.unshadowed_lights] == ["/World/Off"]
    assert [(x.path, x.kind) for x in s.skipped_lights] == [("/World/Portal", "PortalLight")]
    assert "not honoured" in s.skipped_lights[0].reason


def test_camera_perspective_and_orthographic():
    from pxr import UsdGeom

    st = make_stage()
    add_camera(st, "/World/Cam", (0, -5, 5), (0, 0, 0), focal=20.955 / 2)
    o = add_camera(st, "/World/Ortho", (0, 0, 10), (0, 0, 0), up=(0, 1, 0))
    o.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    s = wsoft.load_scene(st)
    cam, ortho = s.cameras
    assert cam.tan_half[0] == pytest.approx(1.0)  # aperture = 2 * focal -> 90 degrees
    assert np.allclose(cam.position, [0, -5, 5])
    fwd = -cam.to_world[:3, 2]
    assert np.allclose(fwd, np.array([0, 5, -5]) / np.sqrt(50), atol=1e-6)
    assert ortho.orthographic and ortho.tan_half[0] == pytest.approx(20.955 / 20)


def test_time_code_selects_samples():
    from pxr import Gf, UsdGeom

    st = make_stage()
    q = add_quad(st, "/World/Q", (0, 0, 0), 1)
    op = UsdGeom.Xformable(q).AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 1.0)
    op.Set(Gf.Vec3d(0, 0, 10), 2.0)
    st.SetStartTimeCode(1)
    st.SetEndTimeCode(2)
    assert wsoft.load_scene(st).points[:, 2].max() == pytest.approx(0)
    assert wsoft.load_scene(st, time=2).points[:, 2].max() == pytest.approx(10)


# -- bad input -------------------------------------------------------------------------------


def test_broken_file(tmp_path):
    bad = tmp_path / "broken.usda"
    bad.write_text("#usda 1.0\n( this is not usd\n")
    with pytest.raises(SceneError) as e:
        wsoft.load_scene(str(bad))
    assert str(bad) in e.value.line() and "\n" not in e.value.line()


def test_missing_file(tmp_path):
    with pytest.raises(SceneError, match="file not found"):
        wsoft.load_scene(str(tmp_path / "none.usda"))


def test_out_of_range_face_index():
    from pxr import UsdGeom

    st = make_stage()
    m = UsdGeom.Mesh.Define(st, "/World/Bad")
    m.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    m.CreateFaceVertexCountsAttr([3])
    m.CreateFaceVertexIndicesAttr([0, 1, 7])
    with pytest.raises(SceneError) as e:
        wsoft.load_scene(st)
    assert "/World/Bad" in e.value.line() and "out of range" in e.value.line()


def test_nan_points():
    from pxr import UsdGeom

    st = make_stage()
    m = UsdGeom.Mesh.Define(st, "/World/Nan")
    m.CreatePointsAttr([(0, 0, 0), (1, float("nan"), 0), (0, 1, 0)])
    m.CreateFaceVertexCountsAttr([3])
    m.CreateFaceVertexIndicesAttr([0, 1, 2])
    with pytest.raises(SceneError) as e:
        wsoft.load_scene(st)
    assert "/World/Nan" in e.value.line() and "points[1]" in e.value.line()


def test_no_shadow_casting_light_is_an_error():
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 1)
    add_rect_light(st, "/World/Off", (0, 0, 2), 1, 1, shadow=False)
    s = wsoft.load_scene(st)
    with pytest.raises(SceneError, match="no shadow-casting light"):
        wsoft.render(s, "hard", width=8, height=8, device="cpu")


def test_closed_orientation():
    from wsoft.scene.usd_mesh import closed_orientation

    # a unit cube, outward counter-clockwise faces
    p = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    tris = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    assert closed_orientation(p, tris) == 1
    assert closed_orientation(p, tris[:, ::-1]) == -1  # inside out
    assert closed_orientation(p, tris[:-2]) == 0  # a face missing: open
    flipped = tris.copy()
    flipped[0] = flipped[0][::-1]
    assert closed_orientation(p, flipped) == 0  # inconsistent winding
    assert closed_orientation(p, np.concatenate([tris, tris[:2]])) == 0  # non-manifold (doubled face)


def test_closed_meshes_flagged_on_load():
    s = wsoft.load_scene(__import__("conftest").scene_path("contact.usda"))
    ground = s.tri_prim == next(i for i, p in enumerate(s.prims) if "Ground" in p)
    assert np.all(s.tri_closed[ground] == 0) and np.all(s.tri_closed[~ground] == 1)


def test_dynamic_casters_and_baked_light():
    """Salzman's split: dynamic casters (animated transform, time-sampled points or wsoft:dynamic)
    and static receivers with baked lighting."""
    from pxr import Gf, Sdf, UsdGeom

    st = make_stage()
    g = add_quad(st, "/World/Static/Ground", (0, 0, 0), 5)
    pv = UsdGeom.PrimvarsAPI(g).CreatePrimvar("wsoft:bakedLight", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
    pv.Set([(0.1, 0.2, 0.3), (0.4, 0.5, 0.6), (0.7, 0.8, 0.9), (1.0, 1.0, 1.0)])
    UsdGeom.Xform.Define(st, "/World/Walker")
    add_quad(st, "/World/Walker/Body", (0, 0, 1), 0.3)
    op = UsdGeom.Xformable(st.GetPrimAtPath("/World/Walker")).AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 1.0)
    op.Set(Gf.Vec3d(1, 0, 0), 2.0)
    flagged = add_quad(st, "/World/Ball", (2, 0, 1), 0.3)
    flagged.GetPrim().CreateAttribute("wsoft:dynamic", Sdf.ValueTypeNames.Bool).Set(True)
    morph = add_quad(st, "/World/Morph", (-2, 0, 1), 0.3)
    morph.GetPointsAttr().Set([(-2.3, -0.3, 1), (-1.7, -0.3, 1), (-1.7, 0.3, 1), (-2.3, 0.3, 1)], 1.0)
    morph.GetPointsAttr().Set([(-2.3, -0.3, 2), (-1.7, -0.3, 2), (-1.7, 0.3, 2), (-2.3, 0.3, 2)], 2.0)
    add_rect_light(st, "/World/L", (0, 0, 4), 1, 1)
    s = wsoft.load_scene(st)
    assert s.dynamic_prims() == ["/World/Walker/Body", "/World/Ball", "/World/Morph"]
    ground = s.tri_prim == s.prims.index("/World/Static/Ground")
    assert not s.tri_dynamic[ground].any()
    assert np.allclose(s.tri_baked[ground][0, 0], (0.1, 0.2, 0.3))
    assert np.isnan(s.tri_baked[~ground]).all()
    p = wsoft.plan(s, ["hard"])
    assert p["dynamic_prims"] == s.dynamic_prims() and p["baked_light_triangles"] == 2


def test_lightmapped_bridge_scene():
    s = wsoft.load_scene(__import__("conftest").scene_path("lightmapped_bridge.usda"))
    assert {"/World/Dynamic/Ball"} <= set(s.dynamic_prims())
    assert any(p.startswith("/World/Dynamic/Character/") for p in s.dynamic_prims())
    assert not any(p.startswith("/World/Static/") for p in s.dynamic_prims())
    assert s.tri_baked is not None and np.isfinite(s.tri_baked[~s.tri_dynamic]).all()
    assert s.time == 1.0 and [l.name for l in s.lights] == ["Sun", "Torch"]


def _instancer_stage(*, invisible=(3,), indices=(0, 1, 0, 1), time_samples=False):
    """A PointInstancer of two prototypes (a box under an Xform with its own translate, and a cube)
    over a ground: positions, scales, orientations (one turned 90 degrees about z), invisibleIds."""
    from pxr import Gf, Sdf, UsdGeom, Vt

    from wsoft.stages import add_box

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    pi = UsdGeom.PointInstancer.Define(st, "/World/Trees")
    UsdGeom.XformCommonAPI(pi).SetTranslate(Gf.Vec3d(0, 0, 0.5))
    UsdGeom.XformCommonAPI(UsdGeom.Xform.Define(st, "/World/Trees/Protos/Tree")).SetTranslate(Gf.Vec3d(0, 0, 0.25))
    add_box(st, "/World/Trees/Protos/Tree/Box", (-0.1, -0.3, 0.0), (0.1, 0.3, 0.2))
    UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/Trees/Protos/Tree/Box")).SetTranslate(Gf.Vec3d(0.05, 0, 0))
    add_box(st, "/World/Trees/Protos/Cube", (-0.1, -0.1, -0.1), (0.1, 0.1, 0.1))
    UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/Trees/Protos/Cube")).SetTranslate(Gf.Vec3d(0, 0, 1.0))
    pi.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Trees/Protos/Tree"), Sdf.Path("/World/Trees/Protos/Cube")])
    pi.CreateProtoIndicesAttr(list(indices))
    pos = pi.CreatePositionsAttr()
    if time_samples:
        pos.Set([(-1, 0, 0), (0, 0, 0), (1, 0, 0), (0, 1, 0)], 1.0)
        pos.Set([(-1, 0, 0.5), (0, 0, 0.5), (1, 0, 0.5), (0, 1, 0.5)], 2.0)
    else:
        pos.Set([(-1, 0, 0), (0, 0, 0), (1, 0, 0), (0, 1, 0)])
    pi.CreateScalesAttr([(1, 1, 1), (2, 2, 2), (1, 1, 3), (1, 1, 1)])
    q = Gf.Quath(float(np.cos(np.pi / 4)), 0, 0, float(np.sin(np.pi / 4)))
    pi.CreateOrientationsAttr(Vt.QuathArray([Gf.Quath(1, 0, 0, 0), Gf.Quath(1, 0, 0, 0), q, Gf.Quath(1, 0, 0, 0)]))
    pi.CreateInvisibleIdsAttr(list(invisible))
    add_rect_light(st, "/World/Light", (0, 0, 4), 1, 1)
    add_camera(st, "/World/Cam", (0, -5, 5), (0, 0, 0))
    return st, pi


def test_point_instancer_places_its_prototypes_where_usd_does():
    """A PointInstancer's instances are loaded (flattened: one copy each), at
    the bounds USD itself computes per instance (positions, scales, orientations, the prototypes'
    own transforms), without its invisibleIds, and the prototypes are not drawn where they are
    authored."""
    from pxr import Usd, UsdGeom

    st, pi = _instancer_stage()
    s = wsoft.load_scene(st)
    names = s.prims
    assert names == ["/World/Ground", "/World/Trees/Protos/Tree/Box@/World/Trees[0]", "/World/Trees/Protos/Cube@/World/Trees[1]",
                     "/World/Trees/Protos/Tree/Box@/World/Trees[2]"]
    bc = UsdGeom.BBoxCache(Usd.TimeCode.Default(), ["default"])
    for k, name in enumerate(names[1:], start=1):
        i = int(name.split("[")[1].rstrip("]"))
        r = bc.ComputePointInstanceWorldBound(pi, i).ComputeAlignedRange()
        p = s.points[np.unique(s.triangles[s.tri_prim == k])]
        assert np.allclose(p.min(axis=0), np.array(r.GetMin()), atol=1e-5) and np.allclose(p.max(axis=0), np.array(r.GetMax()), atol=1e-5)
    assert not any(n.startswith("/World/Trees/Protos") and "@" not in n for n in names)


def test_point_instancer_casts_the_shadows_of_the_same_meshes_authored_in_place():
    """The reference's V over an instanced stage equals the one over the same triangles written
    out as plain meshes (the flattened scene, built from the instancer's own world points)."""
    from wsoft.stages import make_stage as mk

    st, _ = _instancer_stage()
    inst = wsoft.load_scene(st)
    from pxr import UsdGeom

    flat = mk()
    add_rect_light(flat, "/World/Light", (0, 0, 4), 1, 1)
    add_camera(flat, "/World/Cam", (0, -5, 5), (0, 0, 0))
    for k, name in enumerate(inst.prims):
        t = inst.triangles[inst.tri_prim == k]
        used, remap = np.unique(t, return_inverse=True)
        m = UsdGeom.Mesh.Define(flat, f"/World/M{k}")
        m.CreatePointsAttr([tuple(map(float, p)) for p in inst.points[used]])
        m.CreateFaceVertexCountsAttr([3] * len(t))
        m.CreateFaceVertexIndicesAttr([int(x) for x in remap.ravel()])
        m.CreateDoubleSidedAttr(True)
    kw = {"width": 64, "height": 48, "samples": 16}
    a = wsoft.render(inst, "reference", **kw)
    b = wsoft.render(wsoft.load_scene(flat), "reference", **kw)
    assert np.array_equal(a.V, b.V)
    assert (a.V[a["A"] > 0] < 0.5).sum() > 50  # the instances do shadow the ground


def test_point_instancer_time_samples_bad_indices_and_missing_prototypes():
    st, _ = _instancer_stage(time_samples=True)
    z1 = wsoft.load_scene(st, time=1.0).points[:, 2].max()
    z2 = wsoft.load_scene(st, time=2.0).points[:, 2].max()
    assert z2 == pytest.approx(z1 + 0.5, abs=1e-5)
    assert wsoft.load_scene(st, time=1.0).tri_dynamic[wsoft.load_scene(st, time=1.0).tri_prim > 0].all()  # moving instances
    st, _ = _instancer_stage(indices=(0, 1, 5, 1))
    with pytest.raises(SceneError, match=r"/World/Trees.*protoIndices\[2\] = 5 is out of range for 2 prototypes"):
        wsoft.load_scene(st)
    st, pi = _instancer_stage()
    pi.GetPrototypesRel().ClearTargets(True)
    with pytest.raises(SceneError, match=r"/World/Trees.*no prototypes"):
        wsoft.load_scene(st)
    st, pi = _instancer_stage()
    pi.GetPositionsAttr().Set([(0, 0, 0)])  # one position for four protoIndices
    with pytest.raises(SceneError, match=r"/World/Trees.*do not match its 4 protoIndices"):
        wsoft.load_scene(st)


def test_shadow_link_and_shadow_distance_are_applied_not_warned():
    """UsdLux controls wsoft applies (a shadowLink collection that excludes casters, as
    Usd.CollectionAPI computes membership, and a finite inputs:shadow:distance) are read onto the
    light, with no warning; the defaults (everything included, -1) are silent.
    Rendering them: tests/test_shadow_link.py."""
    from pxr import Sdf, UsdLux

    from wsoft.stages import add_box

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    add_box(st, "/World/Box", (-0.3, -0.3, 0.2), (0.3, 0.3, 0.8))
    add_rect_light(st, "/World/Light", (0, 0, 4), 1, 1)
    add_camera(st, "/World/Cam", (0, -5, 5), (0, 0, 0))
    assert not [w for w in wsoft.load_scene(st).warnings if "shadow" in w]
    light = UsdLux.LightAPI(st.GetPrimAtPath("/World/Light"))
    light.GetShadowLinkCollectionAPI().GetExcludesRel().AddTarget(Sdf.Path("/World/Box"))
    UsdLux.ShadowAPI.Apply(st.GetPrimAtPath("/World/Light")).CreateShadowDistanceAttr(2.5)
    s = wsoft.load_scene(st)
    assert not [x for x in s.warnings if "/World/Light" in x]
    assert [s.prims[i] for i in s.lights[0].shadow_excluded] == ["/World/Box"] and s.lights[0].shadow_distance == 2.5
