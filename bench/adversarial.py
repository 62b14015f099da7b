"""The adversarial corpus: stages a new or a hostile user feeds wsoft, and what each must give.

Every case writes a small stage (or a broken file) into a folder and says what is expected of
every technique that supports it: ``ok`` (exit 0, no NaN, and where the answer is known, the
answer: full shadow under a lamp shade, the occluder's shadow unchanged by a far huge triangle)
or ``error`` (exit 2, one line naming the file and the prim, no traceback). Warnings a case must
raise are listed too. The cases run through the command line in-process, exactly as a user runs
them (``wsoft render STAGE -t TECH --out ... --stats ...``).

``tests/test_adversarial.py`` runs every case x every technique on CPU in CI; ``wsoft bench
adversarial`` writes the same table to ``reports/adversarial.md``, with what each technique does
with a light inside a closed mesh.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from wsoft.bench.stages import add_box, add_camera, add_quad, add_rect_light, add_sun, make_stage

W, H = 48, 36  # frame size of every case (small: the corpus runs in CI)
MAP = 256  # texels (cells) per side of every technique's light map or grid (its size_param)
REF_SAMPLES = 64


# --------------------------------------------------------------------------- stage builders


def _save(stage, folder: str, name: str, ext: str = ".usda") -> str:
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
    from pxr import UsdGeom

    m = UsdGeom.Mesh.Define(st, path)
    m.CreatePointsAttr(pts)
    m.CreateFaceVertexCountsAttr([3])
    m.CreateFaceVertexIndicesAttr([0, 1, 2])
    return m


def _sphere_mesh(st, path: str, center, radius: float, n: int = 16):
    """A closed, outward-wound UV sphere."""
    from pxr import UsdGeom

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
    m = UsdGeom.Mesh.Define(st, path)
    m.CreatePointsAttr([tuple(map(float, p)) for p in pts])
    m.CreateFaceVertexCountsAttr(counts)
    m.CreateFaceVertexIndicesAttr(idx)
    return m


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
    from pxr import UsdGeom

    st = _base()
    m = UsdGeom.Mesh.Define(st, "/World/Degenerate")
    m.CreatePointsAttr([(0, 0, 2), (0, 0, 2), (1, 1, 2), (2, 2, 2)])
    m.CreateFaceVertexCountsAttr([3, 3])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 0, 2, 3])
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


def same_as(other: str):
    def check(ch, base, technique="", frames=None) -> str | None:
        return _same_v(ch, frames[other], other)

    check.__doc__ = f"The same V as the stage {other!r} on the same pixels."
    check.wants = other
    return check


def ground_dark(ch, base=None, technique="") -> str | None:
    """The ground's top is dark (the light lies in or below its plane)."""
    g = _covered(ch) & (np.abs(ch["P.Z"]) < 1e-4)
    return None if g.sum() > 100 and ch["V"][g].max() == 0.0 else f"max V {ch['V'][g].max() if g.any() else -1:.3f} on {g.sum()} ground pixels"


@dataclass
class Case:
    name: str
    build: Callable[[str], str]
    expect: str = "ok"  # ok | error
    message: tuple[str, ...] = ()  # substrings of the error line (error) or of some warning (ok)
    check: Callable | None = None
    base: str = "base"  # the stage 'same as base' compares with
    silent_before: bool = False  # one of the silent wrong answers or tracebacks (for the report)
    warn_instead: bool = False  # a technique that misses the answer must say so in a warning with ``message``
    map_size: int = MAP  # texels (cells) per side of the techniques' light maps or grids (their size_param)
    note: str = ""


CASES: list[Case] = [
    Case("lamp_rect", b_lamp_rect, check=all_dark, silent_before=True, map_size=1024,
         note="rect light inside a closed box (lamp shade); 1024² maps (at 256² essm/vssm leak 0.09-0.10 at the shade's rim)"),
    Case("lamp_sphere", b_lamp_sphere, check=all_dark, message=("cube map",), warn_instead=True, silent_before=True,
         note="sphere light inside a closed box: beyond a single frustum"),
    Case("huge_far_triangle", b_huge_far_triangle, check=same_as_base, silent_before=True, note="one triangle with corners at +-1e7, out of view"),
    Case("huge_far_triangle_sun", b_huge_far_triangle_sun, check=same_as_base, base="base_sun", silent_before=True,
         note="the same under a 2-degree sun"),
    Case("point_3e38", b_point_3e38, check=same_as_base, silent_before=True, note="a sliver triangle reaching 3e38"),
    Case("points_1e30", b_points_1e30, check=same_as_base, note="a triangle at 1e30"),
    Case("thin_plate_behind", b_thin_plate_behind, check=all_dark, silent_before=True, note="double-sided plate lit from behind"),
    Case("sphere", b_sphere, check=far_side_dark, silent_before=True, note="closed sphere: far side dark, top lit"),
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
    Case("cutout_usdz", b_cutout_usdz, check=same_as("cutout_8bit"), silent_before=True, note="cutout texture inside a .usdz"),
    Case("cutout_truncated_png", b_cutout_truncated_png, message=("cannot be read",), note="truncated PNG: warned, opaque"),
    Case("zero_width_rect", b_zero_width_rect, message=("zero width",), note="RectLight of width 0"),
    Case("inverted_clip", b_inverted_clip, message=("clippingRange",), note="camera clipping range inverted"),
    Case("missing_sublayer", b_missing_sublayer, message=("not_there.usda",), note="a sublayer that is not there"),
    Case("missing_reference", b_missing_reference, message=("no_such_asset.usda",), note="a reference that is not there"),
    Case("rect_nan_width", b_rect_nan_width, "error", ("/World/Light", "inputs:width"), silent_before=True),
    Case("rect_inf_width", b_rect_inf_width, "error", ("/World/Light", "inputs:width"), silent_before=True),
    Case("sphere_nan_radius", b_sphere_nan_radius, "error", ("/World/Light", "inputs:radius"), silent_before=True),
    Case("disk_inf_radius", b_disk_inf_radius, "error", ("/World/Light", "inputs:radius"), silent_before=True),
    Case("disk_negative_radius", b_disk_negative_radius, "error", ("/World/Light", "inputs:radius"), silent_before=True),
    Case("exposure_huge", b_exposure_huge, "error", ("/World/Light", "exposure"), silent_before=True, note="was an OverflowError traceback"),
    Case("nan_transform", b_nan_transform, "error", ("/World/Occluder", "transform"), silent_before=True),
    Case("inf_transform", b_inf_transform, "error", ("/World/Occluder",), silent_before=True),
    Case("negative_count", b_negative_count, "error", ("/World/Occluder", "faceVertexCounts"), silent_before=True),
    Case("count_5_minus_2", b_count_5_minus_2, "error", ("/World/Occluder", "faceVertexCounts"), silent_before=True,
         note="was an IndexError traceback"),
    Case("broken_syntax", b_broken_syntax, "error", ("broken_syntax.usda:5:3", "parse error")),
    Case("empty", b_empty, "error", ("no shadow-casting light",)),
    Case("dome_only", b_dome_only, "error", ("/World/Dome",)),
]
BASES = {"base": b_base, "base_sun": b_base_sun}


# what the corpus sets beyond a technique's quick parameters: the reference's samples, and izb
# without anti-aliasing (the checks judge a pixel by its centre sample: an anti-aliased pixel
# mixes what it covers)
CORPUS_PARAMS = {"reference": {"samples": REF_SAMPLES}, "izb": {"aa": "none"}}


def technique_args(technique: str, map_size: int = MAP) -> list[str]:
    """``--set`` arguments of a technique in the corpus: its quick parameters
    (``Technique.quick_params``), ``map_size`` for its map or grid (``Technique.size_param``) and
    :data:`CORPUS_PARAMS`."""
    from wsoft.techniques import get_technique

    cls = get_technique(technique)
    params = {**cls.quick_params, **({cls.size_param: map_size} if cls.size_param else {}), **CORPUS_PARAMS.get(technique, {})}
    return [a for k, v in params.items() for a in ("--set", f"{k}={v}")]


@dataclass
class Result:
    rc: int
    error: str = ""  # the one error line (exit 2)
    warnings: list[str] = field(default_factory=list)
    stats: dict | None = None
    channels: dict | None = None
    stderr: str = ""


def run_cli(stage: str, technique: str, out_dir: str, name: str, map_size: int = MAP) -> Result:
    """``wsoft render STAGE -t TECHNIQUE`` in-process, as a user runs it; the EXR read back."""
    from wsoft.cli import main
    from wsoft.io import read_exr

    exr = os.path.join(out_dir, f"{name}-{technique}.exr")
    stats = os.path.join(out_dir, f"{name}-{technique}.json")
    for p in (exr, stats):
        with contextlib.suppress(FileNotFoundError):
            os.remove(p)
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        rc = main(["render", stage, "-t", technique, "--width", str(W), "--height", str(H), "--device", "cpu",
                   *technique_args(technique, map_size), "--out", exr, "--stats", stats])
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    res = Result(rc=rc, stderr=err.getvalue(), warnings=[ln[len("warning: "):] for ln in lines if ln.startswith("warning: ")])
    errs = [ln for ln in lines if ln.startswith("wsoft: error: ")]
    res.error = errs[0][len("wsoft: error: "):] if errs else ""
    if rc == 0:
        with open(stats) as f:
            res.stats = json.load(f)
        res.channels = read_exr(exr)
    return res


def supports(stage: str, technique: str) -> bool:
    """Does ``technique`` support the stage's light (``ssm`` has no point lights)? Unloadable stages: yes."""
    import wsoft
    from wsoft.errors import WsoftError
    from wsoft.techniques import create

    try:
        scene = wsoft.load_scene(stage)
    except WsoftError:
        return True
    t = create(technique, {})
    return any(t.supports(scene, l) is None for l in scene.lights) or not scene.lights


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


# known defects the corpus found and this issue left alone: (case, technique) -> what and where it is tracked
KNOWN: dict[tuple[str, str], str] = {
    ("sphere", "essm"): "self-shadowing on a curved receiver's lit top (min V 0.75 at 256² and 1024² maps): ESSM fidelity, issue 10",
    ("sphere", "vssm"): "self-shadowing on a curved receiver's lit top (min V 0.83 at 256², 0.17 at 1024²): VSSM's filtered estimate",
}


class Corpus:
    """The cases' stages written into ``folder`` on demand, and their renders (cached per technique)."""

    def __init__(self, folder: str):
        self.folder = folder
        os.makedirs(folder, exist_ok=True)
        self.stages: dict[str, str] = {}
        self.results: dict[tuple[str, str], Result] = {}
        self.by_name = {c.name: c for c in CASES}

    def stage(self, name: str) -> str:
        if name not in self.stages:
            build = BASES.get(name) or self.by_name[name].build
            with _quiet_usd():
                self.stages[name] = build(self.folder)
        return self.stages[name]

    def result(self, name: str, technique: str) -> Result:
        key = (name, technique)
        if key not in self.results:
            case = self.by_name.get(name)
            self.results[key] = run_cli(self.stage(name), technique, self.folder, name, case.map_size if case else MAP)
        return self.results[key]

    def frame(self, name: str, technique: str) -> dict | None:
        return self.result(name, technique).channels

    def run(self, case: Case, technique: str) -> tuple[Result | None, list[str]]:
        """(result, problems); (None, []) when the technique does not support the stage's light."""
        if not supports(self.stage(case.name), technique):
            return None, []
        res = self.result(case.name, technique)
        return res, judge(case, technique, res, lambda other: self.frame(other, technique))


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


def run_all(folder: str, techniques: list[str], cases: list[Case] | None = None):
    """Every case x technique: yields (case, technique, Result, problems); skips unsupported pairs."""
    corpus = Corpus(folder)
    for case in CASES if cases is None else cases:
        for t in techniques:
            res, problems = corpus.run(case, t)
            if res is not None:
                yield case, t, res, problems


# --------------------------------------------------------------------------- the sweep


def cases(quick: bool = False, devices=None) -> list[dict]:
    return [{"corpus": "adversarial", "frame": f"{W}x{H}", "map": MAP, "ref_samples": REF_SAMPLES}]


def run_case(case: dict, ctx: dict) -> dict:
    import tempfile

    from wsoft.techniques import TECHNIQUES

    rows = []
    with tempfile.TemporaryDirectory() as d:
        for c, t, res, problems in run_all(d, sorted(TECHNIQUES)):
            v = res.channels["V"][res.channels["A"] > 0] if res.channels is not None else np.zeros(0)
            here = lambda x: x.replace(d + os.sep, "")  # noqa: E731  (messages name the stage file, not the temporary folder)
            warned = [w for w in res.warnings if any(m in w for m in c.message)] or res.warnings[:1]
            rows.append({"case": c.name, "technique": t, "expect": c.expect, "rc": res.rc, "problems": [here(x) for x in problems],
                         "error": here(res.error), "warnings": [here(w) for w in warned],
                         "mean_V": float(v.mean()) if v.size else None, "silent_before": c.silent_before, "note": c.note,
                         "known": KNOWN.get((c.name, t), "")})
    return {"results": rows}


def report(rows: list[dict], md, ctx: dict) -> None:
    results = [r for row in rows for r in row["results"]]
    techs = sorted({r["technique"] for r in results})
    names = list(dict.fromkeys(r["case"] for r in results))
    by = {(r["case"], r["technique"]): r for r in results}
    bad = [r for r in results if r["problems"] and not r.get("known")]
    known = [r for r in results if r["problems"] and r.get("known")]
    lines = [
        "# Adversarial corpus: hard inputs x every technique", "",
        f"Command: `{ctx['command']}` (the same cases run in `tests/test_adversarial.py`).", "",
        f"Each case is a small stage rendered through the CLI (`wsoft render STAGE -t TECH`, {W}x{H}, maps {MAP}², "
        f"reference {REF_SAMPLES} samples). A cell is `ok` when the case behaved as it must (exit code, one-line error naming "
        "the prim, the warning, no NaN, and the known answer where there is one), else what went wrong; `-`: the technique "
        "does not support the stage's light. *mean V* is over covered pixels.", "",
        f"**{len(results) - len(bad) - len(known)} of {len(results)} case x technique runs as expected; {len(known)} known defects "
        f"(listed below, left for other issues); {len(bad)} unexpected.**", "",
        "| case | expect | what | " + " | ".join(techs) + " |", "|---|---|---|" + "---|" * len(techs),
    ]
    for n in names:
        first = next(r for r in results if r["case"] == n)
        cells = []
        for t in techs:
            r = by.get((n, t))
            if r is None:
                cells.append("-")
            elif r["problems"] and r.get("known"):
                cells.append("known defect ‡")
            elif r["problems"]:
                cells.append("**" + "; ".join(r["problems"]).replace("|", "/")[:120] + "**")
            elif r["expect"] == "error":
                cells.append("ok (exit 2)")
            else:
                cells.append(f"ok, V̄ {r['mean_V']:.3f}" if r["mean_V"] is not None else "ok")
        lines.append(f"| {n}{' †' if first['silent_before'] else ''} | {first['expect']} | {first['note']} | " + " | ".join(cells) + " |")
    lines += ["", "† one of the issue's silent wrong answers or tracebacks before this corpus existed.", "",
              "‡ known defects the corpus found and left for other issues:", ""]
    lines += [f"* `{r['case']}` x `{r['technique']}`: {r['known']} (measured here: {'; '.join(r['problems'])})" for r in known]
    lines += ["",
              "## What each case says (first technique)", ""]
    for n in names:
        r = next(r for r in results if r["case"] == n)
        said = r["error"] or "; ".join(r["warnings"]) or "(nothing)"
        lines.append(f"* `{n}`: {said}")
    lamp = [by.get(("lamp_sphere", t)) for t in techs]
    lines += ["", "## A light inside a closed mesh", "",
              "A rect light inside a closed box emits through one hemisphere, which a single frustum holds: every technique "
              "gives full shadow (`lamp_rect`). A sphere light inside the box shines all around: a single-frustum map opened "
              "at most 80° off its axis cannot hold the ground beyond, so shadow-map techniques leave those receivers lit "
              "and say so in a warning naming the light (`lamp_sphere`); they would need a cube map, which wsoft does not "
              "build. The reference traces rays and is right everywhere.", "",
              "| technique | lamp_rect mean V | lamp_sphere mean V | lamp_sphere warning |", "|---|---:|---:|---|"]
    for t, r in zip(techs, lamp):
        rr = by.get(("lamp_rect", t))
        w = "yes" if r and any("cube map" in x for x in r["warnings"]) else "no"
        lines.append(f"| {t} | {rr['mean_V'] if rr and rr['mean_V'] is not None else float('nan'):.3f} | "
                     f"{r['mean_V'] if r and r['mean_V'] is not None else float('nan'):.3f} | {w} |")
    md.write_text("\n".join(lines) + "\n")
