"""Stages built from several files: sublayers, references, payloads, variants, usdz; and hard geometry."""

from __future__ import annotations

import numpy as np
from conftest import add_camera, add_quad, add_rect_light, make_stage, scene_path

import wsoft


def _layer_with_quad(path, prim="/Part", center=(0, 0, 0), half=1.0):
    from pxr import Usd, UsdGeom

    st = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(st, UsdGeom.Tokens.z)
    UsdGeom.Xform.Define(st, prim)
    add_quad(st, prim + "/Q", center, half)
    st.SetDefaultPrim(st.GetPrimAtPath(prim))
    st.GetRootLayer().Save()
    return str(path)


def test_sublayer_reference_payload_and_variant(tmp_path):
    from pxr import Gf, Usd, UsdGeom

    sub = _layer_with_quad(tmp_path / "sub.usda", "/Sub", (0, 0, 0), 4)
    ref = _layer_with_quad(tmp_path / "ref.usda", "/Ref", (1, 0, 1), 0.5)
    pay = _layer_with_quad(tmp_path / "pay.usda", "/Pay", (-1, 0, 1), 0.5)
    root = Usd.Stage.CreateNew(str(tmp_path / "root.usda"))
    UsdGeom.SetStageUpAxis(root, UsdGeom.Tokens.z)
    root.GetRootLayer().subLayerPaths.append(sub)
    UsdGeom.Xform.Define(root, "/World")
    root.DefinePrim("/World/R").GetReferences().AddReference(ref)
    root.DefinePrim("/World/P").GetPayloads().AddPayload(pay)
    v = root.DefinePrim("/World/V", "Xform")
    vs = v.GetVariantSets().AddVariantSet("size")
    for name, half in (("small", 0.1), ("big", 0.3)):
        vs.AddVariant(name)
        vs.SetVariantSelection(name)
        with vs.GetVariantEditContext():
            add_quad(root, "/World/V/Q", (0, 2, 1), half)
    vs.SetVariantSelection("big")
    light = add_rect_light(root, "/World/L", (0, 0, 3), 1, 1)
    assert light
    add_camera(root, "/World/Cam", (0, -0.01, 8), (0, 0, 0))
    UsdGeom.XformCommonAPI(root.GetPrimAtPath("/World/R")).SetTranslate(Gf.Vec3d(0, 0, 0.5))
    root.GetRootLayer().Save()

    s = wsoft.load_scene(str(tmp_path / "root.usda"))
    assert sorted(s.prims) == ["/Sub/Q", "/World/P/Q", "/World/R/Q", "/World/V/Q"]
    vq = s.points[s.triangles[s.tri_prim == s.prims.index("/World/V/Q")]].reshape(-1, 3)
    assert np.allclose(np.ptp(vq[:, 0]), 0.6)  # the selected variant ("big")
    rq = s.points[s.triangles[s.tri_prim == s.prims.index("/World/R/Q")]].reshape(-1, 3)
    assert np.allclose(rq[:, 2], 1.5)  # referenced prim moved by the referencing prim's transform
    f = wsoft.render(s, "hard", width=32, height=32, device="cpu")
    assert f.V.min() == 0.0


def test_usdz_package(tmp_path):
    from pxr import UsdUtils

    src = tmp_path / "pkg.usdc"
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 3)
    add_quad(st, "/World/O", (0, 0, 1), 0.5)
    add_rect_light(st, "/World/L", (0, 0, 3), 1, 1)
    st.GetRootLayer().Export(str(src))
    assert UsdUtils.CreateNewUsdzPackage(str(src), str(tmp_path / "pkg.usdz"))
    s = wsoft.load_scene(str(tmp_path / "pkg.usdz"))
    assert s.triangle_count == 4 and len(s.lights) == 1


def test_degenerate_and_edge_on_triangles_stay_finite(device):
    """Zero-area triangles and triangles seen edge-on by the light neither crash nor make NaN."""
    from pxr import UsdGeom, Vt

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 3)
    m = UsdGeom.Mesh.Define(st, "/World/Degenerate")
    m.CreatePointsAttr([(0, 0, 1), (0, 0, 1), (0, 0, 1), (0.5, 0, 1), (1, 0, 1), (1.5, 0, 1)])  # a point and a line
    m.CreateFaceVertexCountsAttr(Vt.IntArray([3, 3]))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 1, 2, 3, 4, 5]))
    e = UsdGeom.Mesh.Define(st, "/World/EdgeOn")  # a vertical wall right under the light: edge-on to it
    e.CreatePointsAttr([(-1, 0.0, 0.5), (1, 0.0, 0.5), (1, 0.0, 1.5), (-1, 0.0, 1.5)])
    e.CreateFaceVertexCountsAttr(Vt.IntArray([4]))
    e.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 1, 2, 3]))
    add_rect_light(st, "/World/L", (0, 0, 3), 0.5, 0.5)
    add_camera(st, "/World/Cam", (0, -4, 4), (0, 0, 0))
    s = wsoft.load_scene(st)
    for tech, kw in (("hard", {}), ("hard", {"conservative": True}), ("reference", {"samples": 16})):
        f = wsoft.render(s, tech, width=48, height=48, device=device, **kw)
        for name, a in f.channels.items():
            assert np.all(np.isfinite(a)), (tech, name)
        assert f.V.min() >= 0 and f.V.max() <= 1


def test_pixel_samples_average_visibility(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    one = wsoft.render(scene, "reference", width=64, height=48, device=device, samples=64)
    four = wsoft.render(scene, "reference", width=64, height=48, device=device, samples=64, pixel_samples=4)
    assert four.stats["counters"]["frame"]["gbuffer_samples"] == 4 * 64 * 48
    partial = (four["A"] > 0) & (four["A"] < 1)
    assert partial.sum() > 0  # silhouettes are partly covered
    assert set(np.unique(four["A"])) <= {0.0, 0.25, 0.5, 0.75, 1.0}
    full = four["A"] == 1
    assert np.abs(four.V[full] - one.V[full]).mean() < 0.05
