"""``load_scene(..., instancing=True)``: PointInstancers and instanceable prims kept instanced.

Each instanced stage is checked against the flat load (``instancing=False``, today's loader): the
instances, flattened here in numpy, give the same world triangles (as a multiset), materials, uv,
doubleSided, closed orientation and dynamic flags; ``Scene.flattened()`` gives the flat scene."""

from __future__ import annotations

import os
import shutil
import time

import numpy as np
import pytest
from conftest import add_box, add_camera, add_quad, add_rect_light, make_stage, scene_path

import wsoft
from wsoft.errors import SceneError

W = np.array([1.0, 1.6180339887, 2.7182818285])  # a generic direction: sorts vertices and triangles without ties


# -- world triangles as comparable records ---------------------------------------------------------
def _records(tri_pts, uv, mat, ds, closed, dyn, materials):
    """Per triangle: its corners rotated (winding kept) to start at the one lowest along W, its uv
    rotated alike, and the rest; sorted along W. Materials by content (instance proxies of one
    material have paths of their own)."""
    tri_pts = np.asarray(tri_pts, np.float64)
    first = np.argmin(tri_pts @ W, axis=1)
    rot = (first[:, None] + np.arange(3)[None, :]) % 3
    p = np.take_along_axis(tri_pts, rot[:, :, None], axis=1)
    u = np.take_along_axis(np.asarray(uv, np.float64), rot[:, :, None], axis=1)
    order = np.lexsort(((p[:, 1] @ W), (p.sum(axis=1) @ W)))
    content = [(tuple(np.round(m.albedo, 5)), m.opacity, m.opacity_threshold, m.texture) for m in materials]
    return {"p": p[order], "uv": u[order], "mat": [content[int(m)] for m in np.asarray(mat)[order]],
            "ds": np.asarray(ds, bool)[order], "closed": np.asarray(closed)[order], "dyn": np.asarray(dyn, bool)[order]}


def soup_records(s):
    n = s.triangle_count
    dyn = s.tri_dynamic if s.tri_dynamic is not None else np.zeros(n, bool)
    return _records(s.points[s.triangles], s.tri_uv, s.tri_material, s.tri_double_sided, s.tri_closed, dyn, s.materials)


def instanced_records(s):
    """The soup plus every instance's prototype moved to the world, flattened here (independently of
    ``Scene.flattened``): winding flipped where the instance transform mirrors."""
    parts = {k: [] for k in ("p", "uv", "mat", "ds", "closed", "dyn")}

    def add(p, uv, mat, ds, closed, dyn):
        for k, v in zip(parts, (p, uv, mat, ds, closed, dyn)):
            parts[k].append(np.asarray(v))

    n = s.triangle_count
    add(s.points[s.triangles], s.tri_uv, s.tri_material, s.tri_double_sided, s.tri_closed,
        s.tri_dynamic if s.tri_dynamic is not None else np.zeros(n, bool))
    inst = s.instances
    for k in range(inst.count):
        pr = inst.prototypes[inst.proto[k]]
        M = inst.xform[k]
        pw = (pr.points.astype(np.float64) @ M[:3, :3].T + M[:3, 3]).astype(np.float32)
        flip = [0, 2, 1] if np.linalg.det(M[:3, :3]) < 0 else [0, 1, 2]  # corners (and their uv) in the other order
        dyn = (pr.tri_dynamic if pr.tri_dynamic is not None else np.zeros(pr.triangle_count, bool)) | inst.dynamic[k]
        add(pw[pr.triangles[:, flip]], pr.tri_uv[:, flip], pr.tri_material, pr.tri_double_sided, pr.tri_closed, dyn)
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    return _records(cat["p"], cat["uv"], cat["mat"], cat["ds"], cat["closed"], cat["dyn"], s.materials)


def assert_same_world(a, b):
    assert len(a["p"]) == len(b["p"]) > 0
    scale = max(float(np.abs(a["p"]).max()), 1.0)
    assert np.allclose(a["p"], b["p"], rtol=0, atol=1e-5 * scale)
    assert np.allclose(a["uv"], b["uv"], atol=1e-6)
    assert a["mat"] == b["mat"]
    for k in ("ds", "closed", "dyn"):
        assert np.array_equal(a[k], b[k]), k


# -- stages ------------------------------------------------------------------------------------------
def _cutout_material(st, path, texture):
    from pxr import Gf, Sdf, UsdShade

    mat = UsdShade.Material.Define(st, path)
    surf = UsdShade.Shader.Define(st, path + "/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.2, 0.6, 0.2))
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)
    tex = UsdShade.Shader.Define(st, path + "/Tex")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(texture))
    tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(tex.ConnectableAPI(), "a")
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    return mat


def _material(st, path, color):
    from pxr import Gf, Sdf, UsdShade

    mat = UsdShade.Material.Define(st, path)
    surf = UsdShade.Shader.Define(st, path + "/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    return mat


def _bind(prim, mat):
    from pxr import UsdShade

    UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)


def instancer_stage(tmp_path, *, indices=(0, 1, 0, 1, 0, 1), time_samples=False, link_out=None):
    """A PointInstancer of two prototypes over a ground, saved in tmp_path: ``A`` has its own
    translate and rotate on its root, a closed box and a mirrored (scale -1) closed box; ``B`` a
    nested child Xform holding a cutout quad with st (marked wsoft:dynamic) and a box. Instances have
    positions, orientations and scales, one is hidden by invisibleIds, one mirrors (scale -1 in x)."""
    from pxr import Gf, Sdf, UsdGeom, UsdLux, Vt

    os.makedirs(tmp_path / "textures", exist_ok=True)
    shutil.copy(scene_path("textures/checker_alpha.png"), tmp_path / "textures" / "checker_alpha.png")
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 6)
    pi = UsdGeom.PointInstancer.Define(st, "/World/Trees")
    UsdGeom.XformCommonAPI(pi).SetTranslate(Gf.Vec3d(0.5, 0, 0.25))
    UsdGeom.XformCommonAPI(pi).SetRotate(Gf.Vec3f(0, 0, 15))
    a = UsdGeom.Xform.Define(st, "/World/Trees/Protos/A")
    UsdGeom.XformCommonAPI(a).SetTranslate(Gf.Vec3d(0, 0, 0.3))
    UsdGeom.XformCommonAPI(a).SetRotate(Gf.Vec3f(0, 0, 30))
    _bind(add_box(st, "/World/Trees/Protos/A/Box", (-0.2, -0.3, 0.0), (0.2, 0.3, 0.5)).GetPrim(), _material(st, "/World/Looks/Red", (0.8, 0.1, 0.1)))
    m = add_box(st, "/World/Trees/Protos/A/Mirror", (0.1, -0.1, 0.0), (0.4, 0.1, 0.2))
    UsdGeom.XformCommonAPI(m).SetScale(Gf.Vec3f(-1, 1, 1))
    inner = UsdGeom.Xform.Define(st, "/World/Trees/Protos/B/Inner")
    UsdGeom.XformCommonAPI(inner).SetTranslate(Gf.Vec3d(0.1, 0.0, 0.8))
    UsdGeom.XformCommonAPI(inner).SetScale(Gf.Vec3f(1.5, 1.5, 1.0))
    leaf = add_quad(st, "/World/Trees/Protos/B/Inner/Leaf", (0, 0, 0), 0.4, st=True, dynamic=True)
    _bind(leaf.GetPrim(), _cutout_material(st, "/World/Looks/Cutout", str(tmp_path / "textures" / "checker_alpha.png")))
    add_box(st, "/World/Trees/Protos/B/Inner/Stem", (-0.05, -0.05, -0.8), (0.05, 0.05, 0.0))
    pi.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Trees/Protos/A"), Sdf.Path("/World/Trees/Protos/B")])
    pi.CreateProtoIndicesAttr(list(indices))
    pos = [(-2, -1, 0), (-1, 1, 0), (0, 0, 0), (1, -1, 0), (2, 1, 0), (0, 2, 0)]
    if time_samples:
        pi.CreatePositionsAttr().Set(pos, 1.0)
        pi.GetPositionsAttr().Set([(x, y, z + 0.5) for x, y, z in pos], 2.0)
    else:
        pi.CreatePositionsAttr(pos)
    pi.CreateScalesAttr([(1, 1, 1), (2, 2, 2), (1, 1, 1), (-1, 1, 1), (0.5, 1, 1.5), (1, 1, 1)])
    q = Gf.Quath(float(np.cos(np.pi / 8)), float(np.sin(np.pi / 8)), 0, 0)
    r = Gf.Quath(float(np.cos(np.pi / 5)), 0, 0, float(np.sin(np.pi / 5)))
    pi.CreateOrientationsAttr(Vt.QuathArray([Gf.Quath(1, 0, 0, 0), q, r, r, Gf.Quath(1, 0, 0, 0), q]))
    pi.CreateInvisibleIdsAttr([2])
    light = add_rect_light(st, "/World/Light", (0, 0, 5), 1, 1)
    if link_out:
        link = UsdLux.LightAPI(light.GetPrim()).GetShadowLinkCollectionAPI()
        link.CreateIncludeRootAttr(True)
        link.CreateExcludesRel().SetTargets([Sdf.Path(link_out)])
    add_camera(st, "/World/Cam", (0, -6, 6), (0, 0, 0))
    path = str(tmp_path / "instancer.usda")
    st.GetRootLayer().Export(path)
    return path


def instanceable_stage(tmp_path, *, link_out=None):
    """Instanceable prims: ``/Protos/Tree`` (a class) holds a closed trunk bound to a material inside
    the prototype and a nested instanceable ``Crown`` referencing ``/Protos/Leaf``, whose quad has no
    binding of its own (it inherits one from above the instance). T0 and T1 sit under GroupA (bound
    to Green), T2 under GroupB (Red) and mirrors; T3 is invisible. So the Tree prototype resolves two
    ways: two prototypes, three instances."""
    from pxr import Gf, Sdf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 6)
    leaf = st.CreateClassPrim("/Protos/Leaf")
    leaf.SetTypeName("Xform")
    add_quad(st, "/Protos/Leaf/Quad", (0, 0, 0), 0.3, st=True)
    tree = st.CreateClassPrim("/Protos/Tree")
    tree.SetTypeName("Xform")
    trunk = add_box(st, "/Protos/Tree/Trunk", (-0.1, -0.1, 0), (0.1, 0.1, 1.0))
    _bind(trunk.GetPrim(), _material(st, "/Protos/Tree/Looks/Bark", (0.4, 0.3, 0.2)))
    crown = UsdGeom.Xform.Define(st, "/Protos/Tree/Crown")
    UsdGeom.XformCommonAPI(crown).SetTranslate(Gf.Vec3d(0, 0, 1.2))
    crown.GetPrim().GetReferences().AddInternalReference(Sdf.Path("/Protos/Leaf"))
    crown.GetPrim().SetInstanceable(True)
    green, red = _material(st, "/World/Looks/Green", (0.1, 0.7, 0.1)), _material(st, "/World/Looks/Red", (0.7, 0.1, 0.1))
    for g, mat in (("GroupA", green), ("GroupB", red)):
        _bind(UsdGeom.Xform.Define(st, f"/World/{g}").GetPrim(), mat)
    for name, group, t, s in (("T0", "GroupA", (-1, 0, 0), (1, 1, 1)), ("T1", "GroupA", (1, 0, 0), (1, 1, 2)),
                              ("T2", "GroupB", (0, 2, 0), (-1, 1, 1)), ("T3", "GroupB", (0, -2, 0), (1, 1, 1))):
        x = UsdGeom.Xform.Define(st, f"/World/{group}/{name}")
        UsdGeom.XformCommonAPI(x).SetTranslate(Gf.Vec3d(*t))
        UsdGeom.XformCommonAPI(x).SetRotate(Gf.Vec3f(0, 0, 20))
        UsdGeom.XformCommonAPI(x).SetScale(Gf.Vec3f(*s))
        x.GetPrim().GetReferences().AddInternalReference(Sdf.Path("/Protos/Tree"))
        x.GetPrim().SetInstanceable(True)
        if name == "T3":
            x.MakeInvisible()
    add_rect_light(st, "/World/Light", (0, 0, 5), 1, 1)
    if link_out:
        link = UsdLux.LightAPI(st.GetPrimAtPath("/World/Light")).GetShadowLinkCollectionAPI()
        link.CreateIncludeRootAttr(True)
        link.CreateExcludesRel().SetTargets([Sdf.Path(link_out)])
    add_camera(st, "/World/Cam", (0, -6, 6), (0, 0, 0))
    path = str(tmp_path / "instanceable.usda")
    st.GetRootLayer().Export(path)
    return path


# -- tests -------------------------------------------------------------------------------------------
def test_point_instancer_instances_equal_the_flat_load(tmp_path):
    path = instancer_stage(tmp_path)
    s = wsoft.load_scene(path, instancing=True)
    flat = wsoft.load_scene(path)
    inst = s.instances
    assert s.instanced and inst.count == 5 and len(inst.prototypes) == 2
    assert sorted(inst.instance_id.tolist()) == [0, 1, 3, 4, 5]  # id 2 is invisible
    assert (np.linalg.det(inst.xform[:, :3, :3]) < 0).sum() == 1  # the mirroring instance is kept as is
    assert s.triangle_count == 2 and s.prims[inst.prim[0]] == "/World/Trees"
    assert {s.prims[i] for p in inst.prototypes for i in np.unique(p.tri_prim)} == {
        "/World/Trees/Protos/A/Box", "/World/Trees/Protos/A/Mirror", "/World/Trees/Protos/B/Inner/Leaf", "/World/Trees/Protos/B/Inner/Stem"}
    assert s.total_triangles == flat.triangle_count
    assert_same_world(instanced_records(s), soup_records(flat))
    assert s.has_cutouts and s.cutout_triangle_counts() == flat.cutout_triangle_counts()
    assert (flat.tri_closed != 0).sum() > 0 and flat.tri_dynamic.any() and not flat.tri_dynamic.all()  # the cases happened
    assert np.allclose(s.bounds[0], flat.bounds[0], atol=1.0) and np.allclose(s.bounds[1], flat.bounds[1], atol=1.0)
    assert np.all(s.bounds[0] <= flat.bounds[0] + 1e-5) and np.all(s.bounds[1] >= flat.bounds[1] - 1e-5)  # boxes hold the instances


def test_point_instancer_moving_instances_are_dynamic(tmp_path):
    path = instancer_stage(tmp_path, time_samples=True)
    s = wsoft.load_scene(path, time=2.0, instancing=True)
    assert s.instances.dynamic.all()
    assert_same_world(instanced_records(s), soup_records(wsoft.load_scene(path, time=2.0)))


def test_instanceable_prims_equal_the_flat_load_and_split_on_bindings_from_above(tmp_path):
    path = instanceable_stage(tmp_path)
    s = wsoft.load_scene(path, instancing=True)
    flat = wsoft.load_scene(path)
    inst = s.instances
    assert inst.count == 3 and len(inst.prototypes) == 2  # T0 and T1 share one; T2 (bound to Red above it) has its own
    assert sorted(s.prims[i] for i in inst.prim) == ["/World/GroupA/T0", "/World/GroupA/T1", "/World/GroupB/T2"]
    assert (inst.instance_id == -1).all() and (np.linalg.det(inst.xform[:, :3, :3]) < 0).sum() == 1
    assert len({p.path for p in inst.prototypes}) == 1  # one USD prototype, resolved two ways
    assert s.triangle_count == 2 and s.total_triangles == flat.triangle_count
    leaf_colors = set()
    for p in inst.prototypes:
        quad = np.array([s.prims[i].endswith("/Crown/Quad") for i in p.tri_prim])
        assert quad.any() and not quad.all()  # the nested instance is flattened into the prototype
        leaf_colors |= {tuple(np.round(s.materials[m].albedo, 3)) for m in np.unique(p.tri_material[quad])}
    assert leaf_colors == {(0.1, 0.7, 0.1), (0.7, 0.1, 0.1)}
    assert_same_world(instanced_records(s), soup_records(flat))


def test_flattened_equals_the_flat_load(tmp_path):
    for path in (instancer_stage(tmp_path), instanceable_stage(tmp_path)):
        s = wsoft.load_scene(path, instancing=True)
        flat = wsoft.load_scene(path)
        f = s.flattened()
        assert f.instances is None and f is s.flattened()  # built once
        assert f.prims == flat.prims and np.array_equal(f.points, flat.points) and np.array_equal(f.triangles, flat.triangles)
        # a scene without its stage (edited, or built by hand) is flattened in numpy: the same triangles
        s.changed()
        g = s.flattened()
        assert g is not f and g.instances is None
        assert_same_world(soup_records(g), soup_records(flat))
        assert sorted(g.prims) == sorted(flat.prims)
        assert g.tri_baked is None and g.prim_points.shape == (len(g.prims), 2)
    plain = wsoft.load_scene(path)
    assert plain.flattened() is plain


def test_flattened_of_a_stage_in_memory():
    from pxr import Gf, Sdf, UsdGeom

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    add_box(st, "/Proto/Box", (-0.2, -0.2, 0), (0.2, 0.2, 0.4))
    st.GetPrimAtPath("/Proto").SetSpecifier(Sdf.SpecifierClass)
    for k in range(3):
        x = UsdGeom.Xform.Define(st, f"/World/I{k}")
        UsdGeom.XformCommonAPI(x).SetTranslate(Gf.Vec3d(k - 1.0, 0, 0))
        x.GetPrim().GetReferences().AddInternalReference(Sdf.Path("/Proto"))
        x.GetPrim().SetInstanceable(True)
    add_rect_light(st, "/World/Light", (0, 0, 4), 1, 1)
    s = wsoft.load_scene(st, instancing=True)
    assert s.instances.count == 3 and len(s.instances.prototypes) == 1
    assert_same_world(soup_records(s.flattened()), soup_records(wsoft.load_scene(st)))


def test_no_instances_gives_the_flat_scene():
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    add_box(st, "/World/Box", (-0.2, -0.2, 0), (0.2, 0.2, 0.4))
    add_rect_light(st, "/World/Light", (0, 0, 4), 1, 1)
    a, b = wsoft.load_scene(st, instancing=True), wsoft.load_scene(st)
    assert a.instances is None and not a.instanced and a.flattened() is a
    assert a.prims == b.prims and np.array_equal(a.points, b.points) and np.array_equal(a.triangles, b.triangles)
    assert np.array_equal(a.tri_material, b.tri_material) and np.array_equal(a.tri_closed, b.tri_closed) and a.warnings == b.warnings


def test_only_instances_empty_soup(tmp_path):
    """Everything instanced: the soup is empty, the scene's properties still work."""
    from pxr import Usd

    path = instancer_stage(tmp_path)
    st = Usd.Stage.Open(path)
    st.GetPrimAtPath("/World/Ground").SetActive(False)
    s = wsoft.load_scene(st, instancing=True)
    assert s.triangle_count == 0 and s.instanced and s.total_triangles == wsoft.load_scene(st).triangle_count
    lo, hi = s.bounds
    flat = wsoft.load_scene(st)
    assert np.all(hi > lo) and s.diagonal > 1
    # few instanced vertices: the caster points are the instances' vertices, as the flat load's
    assert np.allclose(np.unique(s.caster_points, axis=0), np.unique(flat.caster_points, axis=0), atol=1e-5)
    assert s.has_cutouts and s.dynamic_prims() == []
    assert_same_world(soup_records(s.flattened()), soup_records(wsoft.load_scene(st)))


def test_city_instanced():
    t = time.perf_counter()
    s = wsoft.load_scene(scene_path("city.usdc"), instancing=True)
    dt = time.perf_counter() - t
    flat = wsoft.load_scene(scene_path("city.usdc"))
    print(f"city: instanced load {dt:.2f} s, {s.instances.count} instances of {len(s.instances.prototypes)} prototypes")
    assert s.instances.count == 344 and len(s.instances.prototypes) == 12
    assert s.triangle_count <= 2 and s.total_triangles == flat.triangle_count == 1_041_866
    assert np.allclose(s.bounds[0], flat.bounds[0], atol=1e-3) and np.allclose(s.bounds[1], flat.bounds[1], atol=1e-3)


def test_forest_instanced():
    """The forest (over 50M triangles once flattened) loads instanced, in a few seconds; it is never
    loaded flat here."""
    t = time.perf_counter()
    s = wsoft.load_scene(scene_path("forest.usdc"), instancing=True)
    dt = time.perf_counter() - t
    inst = s.instances
    print(f"forest: instanced load {dt:.2f} s, {inst.count} instances of {len(inst.prototypes)} prototypes "
          f"({[p.triangle_count for p in inst.prototypes]} triangles), {inst.instanced_triangles:,} instanced triangles")
    assert inst.count >= 10_000 and inst.instanced_triangles >= 50_000_000
    assert 3 <= len(inst.prototypes) <= 4 and all(4_000 <= p.triangle_count <= 7_000 for p in inst.prototypes)
    assert s.triangle_count < 1_000 and s.has_cutouts and len(s.lights) == 2
    assert any(c.path == "/World/Camera" for c in s.cameras)
    assert (inst.instance_id >= 0).all() and len(np.unique(inst.instance_id)) == inst.count
    lo, hi = s.bounds
    assert hi[0] - lo[0] >= 200 and hi[1] - lo[1] >= 200


@pytest.mark.parametrize("bad", ["index", "prototype"])
def test_bad_instancer_inputs_give_the_same_error(tmp_path, bad):
    from pxr import Sdf, Usd

    if bad == "index":
        path = instancer_stage(tmp_path, indices=(0, 1, 0, 7, 0, 1))
    else:
        path = instancer_stage(tmp_path)
        st = Usd.Stage.Open(path)
        st.GetPrimAtPath("/World/Trees").GetRelationship("prototypes").AddTarget(Sdf.Path("/World/Trees/Protos/Nowhere"))
        st.GetRootLayer().Save()
    msgs = []
    for instancing in (False, True):
        with pytest.raises(SceneError) as e:
            wsoft.load_scene(path, instancing=instancing)
        msgs.append(str(e.value))
    assert msgs[0] == msgs[1] and "\n" not in msgs[0]
    assert ("protoIndices[3] = 7 is out of range" if bad == "index" else "prototype /World/Trees/Protos/Nowhere does not exist") in msgs[0]


@pytest.mark.parametrize("stage, out", [("instancer", "/World/Trees"), ("instancer", "/World/Trees/Protos/B/Inner/Leaf"),
                                        ("instanceable", "/World/GroupA/T1/Crown/Quad"), ("instanceable", "/World/Ground")])
def test_shadow_link_exclusion_falls_back_to_the_flat_load(tmp_path, stage, out):
    build = instancer_stage if stage == "instancer" else instanceable_stage
    path = build(tmp_path, link_out=out)
    s = wsoft.load_scene(path, instancing=True)
    flat = wsoft.load_scene(path)
    assert s.instances is None and flat.lights[0].shadow_excluded
    assert s.lights[0].shadow_excluded == flat.lights[0].shadow_excluded and s.prims == flat.prims
    assert [w for w in s.warnings if "shadowLink" in w and "loaded flat" in w] and len(s.warnings) == len(flat.warnings) + 1
    assert s.flattened() is s
