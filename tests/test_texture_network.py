"""The UsdPreviewSurface network that feeds a cutout's opacity (``wsoft.scene.usd_texture``): each
node evaluated as the spec says, checked against the same cutout authored directly (a primvar
named ``st``, st or a texture transformed in Python, a texture per mesh instead of UDIM tiles, PNG
instead of EXR), rendered; nodes wsoft cannot evaluate and textures over the pixel limit are one
warning line each."""

from __future__ import annotations

import struct
import subprocess
import sys
import warnings
import zlib

import numpy as np
import pytest
import warp as wp
from conftest import add_camera, add_quad, add_rect_light, make_stage

import wsoft
from wsoft.errors import SceneError
from wsoft.scene.device import upload_scene
from wsoft.scene.surfaces import Surfaces, sample_alpha
from wsoft.scene.types import WRAP_BLACK, WRAP_CLAMP, WRAP_MIRROR, WRAP_REPEAT

UNIT = [(0, 0), (1, 0), (1, 1), (0, 1)]  # add_quad's corners, counter-clockwise from (-half, -half)


def _pattern(n: int = 16) -> np.ndarray:
    """An alpha image (rows top-down, 1 = opaque) with no symmetry: the top half and a strip on the left."""
    a = np.zeros((n, n))
    a[: n // 2] = 1.0
    a[:, : n // 4] = 1.0
    a[n - 3:, n - 5:n - 2] = 1.0  # a block near the bottom-right corner
    return a


def _png(path, alpha: np.ndarray, mode: str = "RGBA", info: dict | None = None) -> str:
    from PIL import Image, PngImagePlugin

    a = np.round(np.clip(alpha, 0, 1) * 255).astype(np.uint8)
    meta = None
    if info:
        meta = PngImagePlugin.PngInfo()
        for k, v in info.items():
            meta.add_text(k, v)
    img = Image.fromarray(np.dstack([a, a, a, a]), "RGBA") if mode == "RGBA" else Image.fromarray(np.dstack([a, a, a]), "RGB")
    img.save(path, pnginfo=meta)
    return str(path)


def _exr(path, alpha: np.ndarray, header: dict | None = None) -> str:
    import OpenEXR

    a = np.ascontiguousarray(alpha, np.float32)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, **(header or {})},
                      {"R": a, "G": a, "B": a, "A": a}) as f:
        f.write(str(path))
    return str(path)


def _stage():
    """A ground under a rect light, seen by a camera; the occluder comes from each test."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    add_rect_light(st, "/World/Light", (0, 0, 3), 1, 1)
    add_camera(st, "/World/Cam", (0, -4, 5), (0, 0, 0))
    return st


def _primvar(prim, name: str, values, interpolation: str = "vertex"):
    from pxr import Sdf, UsdGeom

    pv = UsdGeom.PrimvarsAPI(prim).CreatePrimvar(name, Sdf.ValueTypeNames.TexCoord2fArray, interpolation)
    pv.Set([tuple(map(float, v)) for v in values])


def _occluder(st, path: str = "/World/Occluder", primvars=None, center=(0, 0, 1), half: float = 1.0):
    """A quad above the ground with texture-coordinate primvars ``{name: values}`` (one per point)."""
    q = add_quad(st, path, center, half)
    for name, values in (primvars if primvars is not None else {"st": UNIT}).items():
        _primvar(q.GetPrim(), name, values)
    return q.GetPrim()


def _cutout(st, path: str, file: str | None, *, channel: str = "a", varname: str | None = "st", transforms=(), texture=None,
            st_value=None, threshold: float = 0.5):
    """A UsdPreviewSurface whose opacity is ``channel`` of a UsdUVTexture of ``file``: its st from a
    UsdPrimvarReader_float2 of ``varname`` through the UsdTransform2d nodes ``transforms`` (dicts
    of their inputs; None: st not connected, ``st_value`` authored), ``texture``: more of its
    inputs ``{name: (Sdf type name, value)}``."""
    from pxr import Sdf, UsdShade

    mat = UsdShade.Material.Define(st, path)
    surf = UsdShade.Shader.Define(st, path + "/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    tex = UsdShade.Shader.Define(st, path + "/Tex")
    tex.CreateIdAttr("UsdUVTexture")
    if file is not None:
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(file))
    for name, (tname, value) in (texture or {}).items():
        tex.CreateInput(name, getattr(Sdf.ValueTypeNames, tname)).Set(value)
    if varname is not None:
        reader = UsdShade.Shader.Define(st, path + "/Reader")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set(varname)
        out = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        for i, t in enumerate(transforms):
            node = UsdShade.Shader.Define(st, f"{path}/Transform{i}")
            node.CreateIdAttr("UsdTransform2d")
            node.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(out)
            for k, v in t.items():
                node.CreateInput(k, Sdf.ValueTypeNames.Float if k == "rotation" else Sdf.ValueTypeNames.Float2).Set(v)
            out = node.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(out)
    elif st_value is not None:
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).Set(st_value)
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(tex.CreateOutput(channel, Sdf.ValueTypeNames.Float))
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(float(threshold))
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    return mat


def _bind(prim, mat):
    from pxr import UsdShade

    UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)


def _load(st):
    s = wsoft.load_scene(st)
    for w in s.warnings:  # messages name paths and nodes, never a Python object's repr
        assert "Sdf.AssetPath(" not in w and "<pxr" not in w and "Usd.Prim(" not in w, w
    return s


def _frames(scene, device):
    """V of ``reference`` (16 samples) and ``hard``, rendered in one graph at 48 x 36."""
    fs = wsoft.render(scene, [("reference", {"samples": 16}), "hard"], width=48, height=36, device=device)
    return {k: fs[k].V for k in ("reference", "hard")}


def _same_frames(a, b, device, differs_from=None):
    """``a`` and ``b`` (scenes) render the same V, and (the case really tests something) unlike
    ``differs_from``."""
    fa, fb = _frames(a, device), _frames(b, device)
    for k in fa:
        assert np.array_equal(fa[k], fb[k]), f"{k}: V differs by up to {np.abs(fa[k] - fb[k]).max():.3g}"
    if differs_from is not None:
        fc = _frames(differs_from, device)
        assert not np.array_equal(fa["reference"], fc["reference"])
        assert 0.0 < fa["reference"].mean() < 1.0


def _plain(tmp_path, image=None, **kw):
    """The plain cutout: the pattern texture over ``st``."""
    st = _stage()
    occ = _occluder(st)
    _bind(occ, _cutout(st, "/World/Looks/Plain", image or _png(tmp_path / "plain.png", _pattern()), **kw))
    return st


def _opaque():
    st = _stage()
    _occluder(st)
    return st


# --------------------------------------------------------------------------- the primvar a reader names


def test_varname_names_the_primvar(tmp_path, device):
    """A reader of ``uv`` on a mesh whose coordinates are in ``uv`` (and an ``st`` that is something
    else) renders as the same cutout over ``st``."""
    png = _png(tmp_path / "p.png", _pattern())
    st = _stage()
    occ = _occluder(st, primvars={"uv": UNIT, "st": [(0, 0)] * 4})
    _bind(occ, _cutout(st, "/World/Looks/Uv", png, varname="uv"))
    s = _load(st)
    plain = _load(_plain(tmp_path, png))
    _same_frames(s, plain, device, differs_from=_load(_opaque()))
    assert np.array_equal(s.tri_uv, plain.tri_uv)


def test_geomsubset_materials_read_their_own_primvars(tmp_path, device):
    """One mesh, two GeomSubsets whose materials read ``st`` and ``st1``: each triangle's st comes
    from its own material's primvar; the same as two meshes with those coordinates in ``st``."""
    from pxr import UsdGeom, Vt

    png = _png(tmp_path / "p.png", _pattern())
    flipped = [(1 - u, v) for u, v in UNIT]
    pts = [(-1, -0.5, 1), (0, -0.5, 1), (0, 0.5, 1), (-1, 0.5, 1), (0, -0.5, 1), (1, -0.5, 1), (1, 0.5, 1), (0, 0.5, 1)]
    st = _stage()
    m = UsdGeom.Mesh.Define(st, "/World/Two")
    m.CreatePointsAttr(pts)
    m.CreateFaceVertexCountsAttr([4, 4])
    m.CreateFaceVertexIndicesAttr(list(range(8)))
    m.CreateDoubleSidedAttr(True)
    _primvar(m.GetPrim(), "st", UNIT + UNIT)
    _primvar(m.GetPrim(), "st1", UNIT + flipped)
    a = UsdGeom.Subset.CreateGeomSubset(m, "left", UsdGeom.Tokens.face, Vt.IntArray([0]), "materialBind")
    b = UsdGeom.Subset.CreateGeomSubset(m, "right", UsdGeom.Tokens.face, Vt.IntArray([1]), "materialBind")
    _bind(a.GetPrim(), _cutout(st, "/World/Looks/A", png, varname="st"))
    _bind(b.GetPrim(), _cutout(st, "/World/Looks/B", png, varname="st1"))
    s = _load(st)

    ref = _stage()
    for name, lo, uv, mat in (("L", 0, UNIT, "A"), ("R", 4, flipped, "B")):
        q = UsdGeom.Mesh.Define(ref, f"/World/{name}")
        q.CreatePointsAttr(pts[lo:lo + 4])
        q.CreateFaceVertexCountsAttr([4])
        q.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
        q.CreateDoubleSidedAttr(True)
        _primvar(q.GetPrim(), "st", uv)
        _bind(q.GetPrim(), _cutout(ref, f"/World/Looks/{mat}", png))
    r = _load(ref)
    _same_frames(s, r, device)
    assert np.array_equal(s.tri_uv, r.tri_uv)
    assert np.array_equal(s.tri_uv[4], np.array(flipped[:3], np.float32))  # the right face (after the ground's 2 and the left's 2): st1


def test_missing_primvar_reads_the_readers_fallback(tmp_path):
    from pxr import Sdf, UsdShade

    st = _stage()
    occ = _occluder(st)
    mat = _cutout(st, "/World/Looks/Uv", _png(tmp_path / "p.png", _pattern()), varname="uv")
    UsdShade.Shader(st.GetPrimAtPath("/World/Looks/Uv/Reader")).CreateInput("fallback", Sdf.ValueTypeNames.Float2).Set((0.25, 0.75))
    _bind(occ, mat)
    s = _load(st)
    occ_tris = s.tri_prim == s.prims.index("/World/Occluder")
    assert np.array_equal(s.tri_uv[occ_tris].reshape(-1, 2), np.tile([0.25, 0.75], (6, 1)).astype(np.float32))
    lines = [w for w in s.warnings if "primvars:uv" in w]
    assert len(lines) == 1 and "/World/Occluder" in lines[0] and "/World/Looks/Uv/Reader" in lines[0] and "fallback" in lines[0]


# --------------------------------------------------------------------------- UsdTransform2d


def test_transform2d_equals_st_transformed_in_python(tmp_path, device):
    """Two UsdTransform2d nodes (a 90-degree turn with a translation, then a scale and another
    translation): the same V, bit for bit, as st authored already transformed."""
    png = _png(tmp_path / "p.png", _pattern())
    chain = [{"rotation": 90.0, "translation": (1.0, 0.0)}, {"scale": (0.5, 2.0), "translation": (0.5, -1.0)}]
    st = _stage()
    _bind(_occluder(st), _cutout(st, "/World/Looks/T", png, transforms=chain))
    s = _load(st)

    def python_transform(u, v):
        u, v = -v + 1.0, u  # (u, v) turned 90 degrees counter-clockwise, + (1, 0)
        return u * 0.5 + 0.5, v * 2.0 - 1.0

    ref = _stage()
    _bind(_occluder(ref, primvars={"st": [python_transform(*p) for p in UNIT]}), _cutout(ref, "/World/Looks/T", png))
    r = _load(ref)
    _same_frames(s, r, device, differs_from=_load(_plain(tmp_path, png)))
    assert np.array_equal(s.tri_uv, r.tri_uv)


def test_transform2d_scales_then_rotates_then_translates(tmp_path):
    """result = R(rotation) (in * scale) + translation, rotation counter-clockwise in degrees."""
    st = _stage()
    t = {"rotation": 30.0, "scale": (2.0, 0.5), "translation": (0.25, -0.5)}
    _bind(_occluder(st), _cutout(st, "/World/Looks/T", _png(tmp_path / "p.png", _pattern()), transforms=[t]))
    s = _load(st)
    c, sn = np.cos(np.radians(30)), np.sin(np.radians(30))
    uv = np.array(UNIT, np.float64) * (2.0, 0.5)
    want = uv @ np.array([[c, -sn], [sn, c]]).T + (0.25, -0.5)
    got = s.tri_uv[s.tri_prim == s.prims.index("/World/Occluder")].reshape(-1, 2)
    assert np.allclose(np.unique(got.round(5), axis=0), np.unique(want.round(5), axis=0), atol=1e-5)


# --------------------------------------------------------------------------- UsdUVTexture's inputs


def test_scale_and_bias_equal_a_texture_scaled_in_python(tmp_path, device):
    """``scale = -1, bias = 1`` on an inverted texture renders as the texture itself (clamped, so
    the border plays no part); the stored texels are the node's output."""
    a = _pattern()
    inv = _png(tmp_path / "inv.png", 1 - a)
    clamp = {"wrapS": ("Token", "clamp"), "wrapT": ("Token", "clamp")}
    st = _stage()
    _bind(_occluder(st), _cutout(st, "/World/Looks/Inv", inv, texture={**clamp, "scale": ("Float4", (1.0, 1.0, 1.0, -1.0)),
                                                                      "bias": ("Float4", (0.0, 0.0, 0.0, 1.0))}))
    s = _load(st)
    plain = _load(_plain(tmp_path, texture=clamp))
    _same_frames(s, plain, device, differs_from=_load(_plain(tmp_path, inv, texture=clamp)))
    assert np.array_equal(s.textures[0].data, plain.textures[0].data)
    assert s.textures[0].border == 1.0 and plain.textures[0].border == 0.0


@wp.kernel
def _sample_texture_0(cut: Surfaces, st: wp.array[wp.vec2], out: wp.array[float]):
    i = wp.tid()
    out[i] = sample_alpha(cut, 0, st[i])


def test_black_wrap_is_the_bias_outside_the_image(tmp_path, device):
    """Transparent black, scaled and biased: outside the image the black wrap gives the bias."""
    st = _stage()
    _bind(_occluder(st), _cutout(st, "/World/Looks/B", _png(tmp_path / "p.png", _pattern()), texture={
        "wrapS": ("Token", "black"), "wrapT": ("Token", "black"), "scale": ("Float4", (1, 1, 1, 0.5)), "bias": ("Float4", (0, 0, 0, 0.25))}))
    s = _load(st)
    ds = upload_scene(s, device)
    pts = wp.array(np.array([(3.0, 0.5), (-2.0, 0.5), (0.5, 0.9)], np.float32), dtype=wp.vec2, device=device)
    out = wp.empty(3, dtype=float, device=device)
    wp.launch(_sample_texture_0, dim=3, inputs=[ds.cutouts, pts], outputs=[out], device=device)
    assert np.allclose(out.numpy(), [0.25, 0.25, 0.75])


def test_wrap_use_metadata_reads_the_image_else_black(tmp_path):
    """``useMetadata`` (wrapS / wrapT unauthored): the image's own wrapS / wrapT (PNG text) or
    OpenEXR ``wrapmodes``, else black, as the spec says."""
    cases = [
        (_png(tmp_path / "none.png", _pattern()), (WRAP_BLACK, WRAP_BLACK)),
        (_png(tmp_path / "meta.png", _pattern(), info={"wrapS": "clamp", "wrapT": "mirror"}), (WRAP_CLAMP, WRAP_MIRROR)),
        (_exr(tmp_path / "meta.exr", _pattern(), {"wrapmodes": "clamp,periodic"}), (WRAP_CLAMP, WRAP_REPEAT)),
    ]
    for file, want in cases:
        s = _load(_plain(tmp_path, file))
        assert (s.textures[0].wrap_s, s.textures[0].wrap_t) == want, file


def test_missing_texture_takes_the_fallback(tmp_path, device):
    """A texture that cannot be read gives the UsdUVTexture's fallback: (0, 0, 0, 0) cuts the
    occluder away (V as without it); the default fallback's a = 1 is opaque, its r = 0 cuts away."""
    gone = str(tmp_path / "gone.png")
    s = _load(_plain(tmp_path, gone, texture={"fallback": ("Float4", (0.0, 0.0, 0.0, 0.0))}))
    line = [w for w in s.warnings if "gone.png" in w]
    assert len(line) == 1 and "not found" in line[0] and "fallback a = 0" in line[0] and "/World/Looks/Plain/Tex" in line[0]
    empty = _stage()
    assert np.array_equal(_frames(s, device)["reference"], _frames(_load(empty), device)["reference"])
    assert not _load(_plain(tmp_path, gone)).has_cutouts
    red = _load(_plain(tmp_path, gone, channel="r"))
    assert red.has_cutouts and red.materials[red.tri_material[-1]].opacity == 0.0


def test_unconnected_st_reads_one_point(tmp_path):
    """An unconnected st is its value everywhere (a warning), not the mesh's ``st`` primvar."""
    png = _png(tmp_path / "p.png", _pattern())
    for st_value, cut in (((0.75, 0.25), True), ((0.25, 0.75), False)):  # a clear texel of the pattern, an opaque one
        st = _stage()
        _bind(_occluder(st), _cutout(st, "/World/Looks/C", png, varname=None, st_value=st_value))
        s = _load(st)
        occ = s.tri_prim == s.prims.index("/World/Occluder")
        assert np.array_equal(s.tri_uv[occ].reshape(-1, 2), np.tile(st_value, (6, 1)).astype(np.float32))
        assert any("inputs:st is not connected" in w and "/World/Looks/C/Tex" in w for w in s.warnings)
        tex = s.textures[s.materials[s.tri_material[occ][0]].texture]
        x, y = int(st_value[0] * 16), int(st_value[1] * 16)
        assert (tex.data[y, x] < 0.5) == cut


def test_srgb_is_decoded_on_colour_channels(tmp_path):
    """An 8-bit RGB image read through r: ``auto`` (unauthored) and ``sRGB`` decode the sRGB curve
    (0.6 -> 0.318, below a 0.5 threshold: cut away), ``raw`` does not; a is never decoded."""
    rgb = _png(tmp_path / "rgb.png", np.full((4, 4), 0.6), mode="RGB")
    want = ((0.6 + 0.055) / 1.055) ** 2.4
    for space, value in ((None, want), ("sRGB", want), ("raw", 0.6)):
        s = _load(_plain(tmp_path, rgb, channel="r", texture={"sourceColorSpace": ("Token", space)} if space else {}))
        assert abs(float(s.textures[0].data[0, 0]) - value) < 1e-6, space
    rgba = _png(tmp_path / "rgba.png", np.full((4, 4), 0.6))
    assert abs(float(_load(_plain(tmp_path, rgba, texture={"sourceColorSpace": ("Token", "sRGB")})).textures[0].data[0, 0]) - 0.6) < 2e-3


# --------------------------------------------------------------------------- nodes wsoft cannot evaluate, bad values


def test_unevaluable_nodes_warn_and_are_opaque(tmp_path):
    from pxr import Sdf, UsdShade

    png = _png(tmp_path / "p.png", _pattern())
    st = _stage()
    occ = _occluder(st)
    mat = _cutout(st, "/World/Looks/M", png)
    other = UsdShade.Shader.Define(st, "/World/Looks/M/Noise")
    other.CreateIdAttr("ND_noise2d_vector2")
    tex = UsdShade.Shader(st.GetPrimAtPath("/World/Looks/M/Tex"))
    tex.GetInput("st").ConnectToSource(other.CreateOutput("out", Sdf.ValueTypeNames.Float2))
    _bind(occ, mat)
    s = _load(st)
    assert not s.has_cutouts
    line = [w for w in s.warnings if "ND_noise2d_vector2" in w]
    assert len(line) == 1 and "/World/Looks/M/Noise" in line[0] and "opaque" in line[0]


def test_file_authored_as_a_string_is_a_warning(tmp_path):
    from pxr import Sdf, UsdShade

    st = _stage()
    _bind(_occluder(st), _cutout(st, "/World/Looks/S", None))
    UsdShade.Shader(st.GetPrimAtPath("/World/Looks/S/Tex")).CreateInput("file", Sdf.ValueTypeNames.String).Set(str(tmp_path / "p.png"))
    s = _load(st)
    assert not s.has_cutouts and any("inputs:file is a str, not an asset path" in w for w in s.warnings)


@pytest.mark.parametrize("name,tname,value", [("scale", "Float4", (1, 1, 1, float("nan"))), ("bias", "Float4", (0, 0, 0, float("inf")))])
def test_non_finite_texture_input_is_an_error(tmp_path, name, tname, value):
    st = _stage()
    _bind(_occluder(st), _cutout(st, "/World/Looks/N", _png(tmp_path / "p.png", _pattern()), texture={name: (tname, value)}))
    with pytest.raises(SceneError) as exc:
        wsoft.load_scene(st)
    assert "/World/Looks/N/Tex" in exc.value.line() and f"inputs:{name}" in exc.value.line()


def test_non_finite_transform_is_an_error(tmp_path):
    st = _stage()
    _bind(_occluder(st), _cutout(st, "/World/Looks/N", _png(tmp_path / "p.png", _pattern()), transforms=[{"rotation": float("nan")}]))
    with pytest.raises(SceneError) as exc:
        wsoft.load_scene(st)
    assert "/World/Looks/N/Transform0" in exc.value.line() and "inputs:rotation" in exc.value.line()


# --------------------------------------------------------------------------- UDIM, EXR


def _two_faces(st, path: str, uv_right):
    """Two unit squares side by side (faceVarying st: the left over [0, 1]^2, the right over ``uv_right``)."""
    from pxr import UsdGeom

    m = UsdGeom.Mesh.Define(st, path)
    m.CreatePointsAttr([(-1, -0.5, 1), (0, -0.5, 1), (0, 0.5, 1), (-1, 0.5, 1), (1, -0.5, 1), (1, 0.5, 1)])
    m.CreateFaceVertexCountsAttr([4, 4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3, 1, 4, 5, 2])
    m.CreateDoubleSidedAttr(True)
    _primvar(m.GetPrim(), "st", UNIT + list(uv_right), "faceVarying")
    return m.GetPrim()


def test_udim_tiles_equal_a_texture_per_face(tmp_path, device):
    """``tile.<UDIM>.png`` over a mesh whose right face has st in [1, 2] x [0, 1]: the left face
    reads tile 1001, the right tile 1002 (st shifted into it), each clamped at its edges; the same
    V as two meshes with a texture each (clamped)."""
    from pxr import UsdGeom

    a, b = _pattern(), np.rot90(_pattern())
    _png(tmp_path / "tile.1001.png", a)
    _png(tmp_path / "tile.1002.png", b)
    st = _stage()
    _bind(_two_faces(st, "/World/Two", [(u + 1, v) for u, v in UNIT]), _cutout(st, "/World/Looks/U", str(tmp_path / "tile.<UDIM>.png")))
    s = _load(st)

    clamp = {"wrapS": ("Token", "clamp"), "wrapT": ("Token", "clamp")}
    ref = _stage()
    for name, lo, png in (("L", (0, 1, 2, 3), "a"), ("R", (1, 4, 5, 2), "b")):
        q = UsdGeom.Mesh.Define(ref, f"/World/{name}")
        pts = [(-1, -0.5, 1), (0, -0.5, 1), (0, 0.5, 1), (-1, 0.5, 1), (1, -0.5, 1), (1, 0.5, 1)]
        q.CreatePointsAttr([pts[i] for i in lo])
        q.CreateFaceVertexCountsAttr([4])
        q.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
        q.CreateDoubleSidedAttr(True)
        _primvar(q.GetPrim(), "st", UNIT, "faceVarying")
        _bind(q.GetPrim(), _cutout(ref, f"/World/Looks/{name}", _png(tmp_path / f"{png}.png", a if png == "a" else b), texture=clamp))
    r = _load(ref)
    _same_frames(s, r, device, differs_from=_load(_opaque()))
    assert np.array_equal(s.tri_uv, r.tri_uv)
    assert s.cutout_triangle_counts() == {"/World/Looks/U": 4}
    assert sorted(s.materials[i].tile for i in set(s.tri_material[s.tri_prim == 1])) == [1001, 1002]


def test_udim_relative_path_spanning_and_missing_tiles(tmp_path):
    """A relative UDIM path resolves against its layer; a triangle spanning tiles, one in a tile
    with no file and one outside 1001-1100 are one warning line each."""
    _png(tmp_path / "tile.1001.png", _pattern())
    st = _stage()
    mat = _cutout(st, "/World/Looks/U", "./tile.<UDIM>.png")
    _bind(_two_faces(st, "/World/Two", [(u + 1.5, v) for u, v in UNIT]), mat)
    _bind(_occluder(st, "/World/Far", primvars={"st": [(u - 3, v) for u, v in UNIT]}, center=(0, 0, 1.5), half=0.2), mat)
    path = str(tmp_path / "udim.usda")
    st.GetRootLayer().Export(path)
    s = _load(path)
    assert s.cutout_triangle_counts()["/World/Looks/U"] == 2  # the left face, in tile 1001 (tile 1002 and no tile: fallback a = 1)
    two = [w for w in s.warnings if "/World/Two" in w]
    assert any("2 triangles span UDIM tiles" in w for w in two) and any("1002" in w and "no file" in w for w in two)
    assert any("/World/Far" in w and "outside the UDIM tiles" in w for w in s.warnings)


def test_exr_texture_equals_the_png(tmp_path, device):
    a = _pattern()
    exr = _load(_plain(tmp_path, _exr(tmp_path / "p.exr", a)))
    png = _load(_plain(tmp_path, _png(tmp_path / "p.png", a)))
    _same_frames(exr, png, device)
    assert np.array_equal(exr.textures[0].data, png.textures[0].data)


# --------------------------------------------------------------------------- the pixel limit


def _png_header(path, w: int, h: int) -> str:
    """A PNG that declares ``w`` x ``h`` RGBA pixels and holds none (a header and an end)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)) + chunk(b"IEND", b""))
    return str(path)


@pytest.mark.parametrize("side", [10000, 20000])
def test_texture_over_the_pixel_limit_is_one_warning(tmp_path, side):
    """A 10000^2 (Pillow's decompression-bomb warning) or 20000^2 (its error) texture: not decoded,
    one ``warning`` line naming it and the limit, no Pillow warning."""
    big = _png_header(tmp_path / "big.png", side, side)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = _load(_plain(tmp_path, big))
    assert not [w for w in caught if "DecompressionBomb" in type(w.message).__name__ or "decompression" in str(w.message).lower()]
    lines = [w for w in s.warnings if "big.png" in w]
    assert len(lines) == 1 and "67.1 Mpx" in lines[0] and "MAX_TEXTURE_PIXELS" in lines[0], lines
    assert not s.has_cutouts  # the fallback's a = 1


def test_pixel_limit_applies_to_png_and_exr(tmp_path, monkeypatch):
    import wsoft.scene.usd_texture as usd_texture

    monkeypatch.setattr(usd_texture, "MAX_TEXTURE_PIXELS", 100)
    for file in (_png(tmp_path / "p.png", _pattern()), _exr(tmp_path / "p.exr", _pattern())):
        s = _load(_plain(tmp_path, file))
        lines = [w for w in s.warnings if "16 x 16" in w]
        assert len(lines) == 1 and "limit of 100 pixels" in lines[0] and not s.has_cutouts


def test_pixel_limit_on_the_command_line_is_one_line(tmp_path):
    """``wsoft plan`` in a fresh process (Pillow's warnings print from Python's warning machinery):
    the 10000^2 texture is one ``warning:`` line naming it, nothing else mentions it."""
    stage = str(tmp_path / "big.usda")
    st = _plain(tmp_path, _png_header(tmp_path / "big.png", 10000, 10000))
    st.GetRootLayer().Export(stage)
    r = subprocess.run([sys.executable, "-m", "wsoft", "plan", stage], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    out = r.stdout + r.stderr
    assert "DecompressionBomb" not in out and "decompression bomb" not in out
    lines = [ln for ln in out.splitlines() if "big.png" in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: ") and "67.1 Mpx" in lines[0], out
