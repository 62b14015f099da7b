"""``wsoft bake``: a technique's visibility at mesh vertices (and texel centres), written as a USD
layer of overs: exact values against the parallel-rectangle answer, the layer composing over its
stage, time samples over a moving character, textures with their UsdUVTexture hookup, bad input."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, add_box, add_quad, add_rect_light, make_stage, parallel_rect_exact, scene_path, wsoft_cli, skip_if_no_local_lights

import wsoft
from wsoft.baking import fill_from_nearest, texel_coverage
from wsoft.io import read_exr
from wsoft.techniques import TECHNIQUES

HALF = 2.45  # the ground's half side: no vertex of the 40 x 40 grid lies within 0.03 of the hard shadow's edge (x, y = 1.5)


def add_grid(stage, path: str, half: float, n: int, z: float = 0.0, st: bool = False):
    """An ``n x n`` grid of quads over [-half, half]^2 at height ``z``, facing +z; ``st`` from 0 to 1 over it."""
    from pxr import Sdf, UsdGeom

    xs = np.linspace(-half, half, n + 1)
    pts = [(float(x), float(y), z) for y in xs for x in xs]
    idx = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            idx += [a, a + 1, a + n + 2, a + n + 1]
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(pts)
    mesh.CreateFaceVertexCountsAttr([4] * (n * n))
    mesh.CreateFaceVertexIndicesAttr(idx)
    if st:
        pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
        pv.Set([((x + half) / (2 * half), (y + half) / (2 * half)) for x, y, _ in pts])
    return mesh


def parallel_stage(n: int = 40, st: bool = False):
    """box_plane's geometry: a 1 x 1 rect light at z = 3 over a 2 x 2 occluder at z = 1, over a
    subdivided ground (``n x n`` quads) at z = 0."""
    stage = make_stage()
    add_grid(stage, "/World/Ground", HALF, n, st=st)
    add_quad(stage, "/World/Occluder", (0.0, 0.0, 1.0), 1.0)
    add_rect_light(stage, "/World/Light", (0.0, 0.0, 3.0), 1.0, 1.0)
    return stage


def primvar(stage_or_layer, path: str, light: str = "Light", time=None):
    """(values, interpolation) of ``primvars:wsoft:visibility:<light>`` on ``path``."""
    from pxr import Usd, UsdGeom

    stage = stage_or_layer if isinstance(stage_or_layer, Usd.Stage) else Usd.Stage.Open(stage_or_layer)
    pv = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(path)).GetPrimvar(f"wsoft:visibility:{light}")
    assert pv, f"no visibility primvar on {path}"
    v = pv.Get(Usd.TimeCode.Default() if time is None else time)
    return np.asarray(v, np.float64), str(pv.GetInterpolation())


def ground_xy(stage):
    from pxr import UsdGeom

    return np.asarray(UsdGeom.Mesh(stage.GetPrimAtPath("/World/Ground")).GetPointsAttr().Get(), np.float64)


# -- exact values at the vertices ------------------------------------------------------------------


def test_reference_at_the_vertices_is_the_exact_parallel_rectangle_answer(device):
    """1024 stratified (32 x 32 jittered) light samples per vertex: only strata the occluder's
    projected edges cross are uncertain, at most 2 x 32 per axis, each a Bernoulli error of variance
    <= 1/4 in units of 1/1024, so sigma <= sqrt(64 / 4) / 1024 ~ 0.004 per axis and ~0.006 where two
    edges cross; 0.03 is 5 sigma over the 1681 vertices. The points' offset (2e-5 of the extent)
    moves the answer by < 1e-4."""
    stage = parallel_stage()
    stats = {}
    layer = wsoft.bake(stage, "reference", samples=1024, device=device, stats=stats)
    v, interp = primvar(layer, "/World/Ground")
    p = ground_xy(stage)
    exact = parallel_rect_exact(p[:, 0], p[:, 1], 3.0, 1.0, 1.0, 0.5)
    pen = (exact > 0.01) & (exact < 0.99)
    assert interp == "vertex" and len(v) == len(p) == 41 * 41
    assert pen.sum() > 150 and (exact == 0).sum() > 50 and (exact == 1).sum() > 500  # penumbra, umbra and light all sampled
    err = np.abs(v - exact)
    assert err.max() < 0.03, err.max()
    assert err[pen].mean() < 0.006, err[pen].mean()
    occ, occ_interp = primvar(layer, "/World/Occluder")
    assert occ_interp == "vertex" and len(occ) == 4 and np.all(occ == 1.0)  # its top sees the whole light
    assert stats["meshes"]["/World/Ground"]["interpolation"] == "vertex" and stats["frames"][0]["points"] == 41 * 41 + 4


def test_hard_at_the_vertices_is_the_point_light_answer(device):
    """``hard`` shadows the light's centre: a vertex is dark exactly where the segment to (0, 0, 3)
    crosses the occluder, |x| and |y| <= 1.5 (no vertex within 0.03 of that edge; a texel of the
    1024^2 map is about 5 mm there)."""
    stage = parallel_stage()
    layer = wsoft.bake(stage, "hard", device=device)
    v, _ = primvar(layer, "/World/Ground")
    p = ground_xy(stage)
    point = np.where((np.abs(p[:, 0]) <= 1.5) & (np.abs(p[:, 1]) <= 1.5), 0.0, 1.0)
    assert (point == 0).sum() > 300
    np.testing.assert_array_equal(v, point)


# ssm at a finite budget has an error that depends on where a point falls on its coarse levels
# (0.018 to 0.05 over the penumbra of this grid's vertices as the grid shifts by 1 cm, 0.028 averaged
# over an eye view's pixels; its bake of the eye view's own points is the eye view, below): level 0 here
BAKE_PARAMS = {"izb": {"aa": "none"}, "reference": {"samples": 64}, "ssm": {"budget": float("inf")},
               "rtdenoise": {"denoiser": "none", "samples": 8}, "vsmap": {"footprint": 0.02}, "smrt": {"footprint": 0.02}}
# techniques refused at their defaults, and the setting their refusal names
REFUSED_AT_DEFAULTS = {"izb": "aa=none", "rtdenoise": "denoiser=none", "vsmap": "footprint=", "smrt": "footprint="}


@pytest.mark.parametrize("name", sorted(TECHNIQUES))
def test_every_technique_bakes_or_says_why(name):
    """Every technique bakes the parallel-rectangle scene within the penumbra tolerance it declares
    for an eye view (x 1.5, + 0.02 for the coarser vertex sampling), or is refused with a reason;
    ``izb`` is refused with its default anti-aliasing and bakes with ``aa=none``, ``rtdenoise`` with
    its default denoiser (a screen-space filter) and bakes its raw rays with ``denoiser=none``."""
    skip_if_no_local_lights(name)
    tech = TECHNIQUES[name](TECHNIQUES[name].make_params({}))
    if name in REFUSED_AT_DEFAULTS:
        assert tech.bake_support() is not None and REFUSED_AT_DEFAULTS[name] in tech.bake_support()
        with pytest.raises(wsoft.ParameterError, match=f"{name} cannot bake"):
            wsoft.bake(parallel_stage(4), name, device="cpu")
    else:
        assert tech.bake_support() is None
    stage = parallel_stage(24)
    layer = wsoft.bake(stage, name, device="cpu", **BAKE_PARAMS.get(name, {}))
    v, _ = primvar(layer, "/World/Ground")
    p = ground_xy(stage)
    exact = parallel_rect_exact(p[:, 0], p[:, 1], 3.0, 1.0, 1.0, 0.5)
    pen = (exact > 0.01) & (exact < 0.99)
    assert np.all(np.isfinite(v)) and np.all((v >= 0) & (v <= 1))
    tol = TECHNIQUES[name].tolerance
    assert np.abs(v - exact)[pen].mean() <= 1.5 * tol.mae_penumbra + 0.02, (name, np.abs(v - exact)[pen].mean())


EYE_PARAMS = {"izb": {"aa": "none"}, "essm": {"anisotropic": False}, "ssm": {"smooth_radius": 0}, "reference": {"samples": 16},
              "rtdenoise": {"denoiser": "none"}, "vsmap": {"footprint": 0.02}, "smrt": {"footprint": 0.02}}


@pytest.mark.parametrize("name", sorted(TECHNIQUES))
def test_a_bake_of_an_eye_views_own_points_is_the_eye_view(name):
    """The bake G-buffer runs a technique's passes unchanged: baking the points an eye view's pixels
    see (their positions and normals, in the same order and the same 48 x 48 packing, every pixel
    covered) gives that eye view's V bit for bit (``pwedge`` to 1e-5: its rays start a few ulps off
    the surface, of the triangle's corners in the eye view and of the points in a bake), at each
    technique's defaults (the reference's random streams included), but for what reads pixel neighbours (``essm``'s anisotropic footprint,
    ``ssm``'s level-of-quality smoothing and ``rtdenoise``'s denoiser, off here) or casts eye rays
    (``izb``'s anti-aliasing, off)."""
    skip_if_no_local_lights(name)
    import warp as wp

    from conftest import add_camera
    from wsoft.baking import BakeContext
    from wsoft.raster.gbuffer import bake_gbuffer
    from wsoft.pipeline.build import as_techniques, visibility_of

    stage = parallel_stage(8)
    add_camera(stage, "/World/Camera", (0.0, 0.0, 8.0), (0.0, 0.0, 0.0), up=(0, 1, 0), focal=36.0)
    scene = wsoft.load_scene(stage)
    params = EYE_PARAMS.get(name, {})
    f = wsoft.render(scene, name, width=48, height=48, device="cpu", **params)
    assert np.all(f["A"] == 1.0)  # every pixel on a surface: the bake's packing is the image's
    P = np.stack([f["P.X"], f["P.Y"], f["P.Z"]], -1).reshape(-1, 3)
    N = np.stack([f["N.X"], f["N.Y"], f["N.Z"]], -1).reshape(-1, 3)
    gb = bake_gbuffer(P, N, np.zeros(len(P), np.int32), None, "cpu")
    assert (gb.width, gb.height) == (48, 48)
    ctx = BakeContext(scene, gb, "cpu")
    (tech,) = as_techniques(name, params)
    key = visibility_of(ctx, ctx.technique(tech, name), scene.lights[0])
    with wp.ScopedDevice("cpu"):
        res, _ = ctx.graph.execute([key], "cpu")
    v = res[key].vis.numpy().reshape(48, 48)
    assert (f.V < 0.99).sum() > 20  # a shadow in view
    if name == "pwedge":  # its wedge tests start a few ulps off the surface: of the triangle's corners in the eye view, of the points in a bake
        np.testing.assert_allclose(v, f.V, rtol=0, atol=1e-5)
    else:
        np.testing.assert_array_equal(v, f.V)


def test_a_bake_gbuffer_has_no_pixel_neighbours():
    """A point has no pixel footprint: ESSM's anisotropic kernels (built from neighbouring samples)
    change nothing on bake points, and SSM's screen-space smoothing of its level of quality finds no
    neighbour (it is the same as smooth_radius = 0)."""
    stage = parallel_stage(24)
    a, _ = primvar(wsoft.bake(stage, "essm", anisotropic=True, device="cpu"), "/World/Ground")
    b, _ = primvar(wsoft.bake(stage, "essm", anisotropic=False, device="cpu"), "/World/Ground")
    np.testing.assert_array_equal(a, b)
    c, _ = primvar(wsoft.bake(stage, "ssm", smooth_radius=5, device="cpu"), "/World/Ground")
    d, _ = primvar(wsoft.bake(stage, "ssm", smooth_radius=0, device="cpu"), "/World/Ground")
    np.testing.assert_array_equal(c, d)
    with pytest.raises(wsoft.ParameterError, match="budget_map"):
        wsoft.bake(stage, "ssm", budget_map="radial", device="cpu")


# -- normals: vertex or faceVarying ------------------------------------------------------------------


def test_the_crease_rule_and_authored_normals():
    """A cube's corners are creases (faceVarying, a normal per face), a grid is smooth (vertex);
    a crease angle over 90 degrees smooths the cube; authored vertex normals are used as authored."""
    from pxr import Usd, UsdGeom

    from wsoft.scene.mesh_points import read_mesh_surface

    stage = make_stage()
    add_box(stage, "/World/Box", (-0.5, -0.5, 0.0), (0.5, 0.5, 1.0))
    add_grid(stage, "/World/Ground", 1.0, 3)
    tc = Usd.TimeCode.Default()

    def surface(path, angle=30.0):
        prim = stage.GetPrimAtPath(path)
        pts = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(), np.float64)
        return read_mesh_surface(prim, tc, pts, np.eye(4), angle)

    box = surface("/World/Box")
    assert box.interpolation == "faceVarying" and box.normals == "geometric" and box.corner_crease.all()
    top = box.corner_normal[box.corner_face == 1]  # (4, 5, 7, 6): the face at z = 1
    np.testing.assert_allclose(top, [[0, 0, 1]] * 4, atol=1e-12)
    assert surface("/World/Ground").interpolation == "vertex"
    smooth = surface("/World/Box", angle=100.0)
    assert smooth.interpolation == "vertex"
    np.testing.assert_allclose(np.linalg.norm(smooth.vertex_normal, axis=1), 1.0)
    np.testing.assert_allclose(np.abs(smooth.vertex_normal), 1 / np.sqrt(3), atol=1e-12)  # corners: the mean of three faces
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Box"))
    mesh.CreateNormalsAttr([(0, 0, 1)] * 8)
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    authored = surface("/World/Box")
    assert authored.interpolation == "vertex" and authored.normals == "authored vertex"
    np.testing.assert_allclose(authored.vertex_normal, [[0, 0, 1]] * 8)


# -- the layer composes over its stage ---------------------------------------------------------------


def test_the_layer_composes_as_a_sublayer(tmp_path):
    """Bake a cube on a ground to a file, open the source stage, add the layer as a sublayer: the
    primvars read through ``UsdGeom.PrimvarsAPI``, vertex on the ground (one value per point),
    faceVarying on the cube (one per face corner: 24), a top corner lit on its top face and dark
    on its sides (hard: the light's centre is behind their planes)."""
    from pxr import Usd, UsdGeom

    stage = make_stage()
    add_quad(stage, "/World/Ground", (0.0, 0.0, 0.0), 3.0)
    add_box(stage, "/World/Box", (-0.5, -0.5, 0.0), (0.5, 0.5, 1.0))
    add_rect_light(stage, "/World/Light", (0.0, 0.0, 3.0), 0.5, 0.5)
    src = tmp_path / "src.usda"
    stage.GetRootLayer().Export(str(src))
    out = tmp_path / "vis.usda"
    layer = wsoft.bake(str(src), "hard", out=str(out), device="cpu")
    assert out.exists() and layer.realPath == str(out)
    data = layer.customLayerData["wsoft"]
    assert data["technique"] == "hard" and data["params"]["shadow_map_size"] == 1024 and data["version"] == wsoft.__version__
    assert data["lights"] == {"/World/Light": "Light"} and data["frames"] == "default"
    assert "hard" in layer.documentation and "sublayer" in layer.documentation

    composed = Usd.Stage.Open(str(src))
    composed.GetRootLayer().subLayerPaths.append("vis.usda")  # relative to the source layer
    g, gi = primvar(composed, "/World/Ground")
    assert gi == "vertex" and len(g) == 4 and np.all(g == 1.0)
    b, bi = primvar(composed, "/World/Box")
    mesh = UsdGeom.Mesh(composed.GetPrimAtPath("/World/Box"))
    idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
    assert bi == "faceVarying" and len(b) == len(idx) == 24
    assert composed.GetPrimAtPath("/World/Box").GetTypeName() == "Mesh"  # the over changes nothing else
    corner = 7  # (0.5, 0.5, 1): on the top face and on two sides
    faces = np.repeat(np.arange(6), 4)
    at = idx == corner
    top = at & (faces == 1)
    assert b[top].tolist() == [1.0] and np.all(b[at & ~top] == 0.0)


# -- time samples over a moving character ----------------------------------------------------------


def test_a_time_sampled_bake_of_the_moving_character():
    """``lightmapped_bridge`` at time codes 1, 13 and 25: every baked mesh has three time samples;
    the deck's values change where the walking character's shadow moves, a box far from it keeps
    the same values, and the layer carries the stage's time range and rate."""
    from pxr import Usd, UsdGeom

    path = scene_path("lightmapped_bridge.usda")
    stats = {}
    layer = wsoft.bake(path, "reference", samples=16, frames="1:25:12", device="cpu", stats=stats)
    assert [f["time"] for f in stats["frames"]] == [1.0, 13.0, 25.0]
    assert all(f["cpu_ms"] > 0 and f["technique_cpu_ms"] > 0 for f in stats["frames"])  # CPU time per frame, beside the wall time
    assert layer.timeCodesPerSecond == 24 and layer.startTimeCode == 1 and layer.endTimeCode == 48
    composed = Usd.Stage.Open(path)
    composed.GetRootLayer().subLayerPaths.append(layer.identifier)
    for mesh in stats["meshes"]:
        for light in ("Sun", "Torch"):
            pv = UsdGeom.PrimvarsAPI(composed.GetPrimAtPath(mesh)).GetPrimvar(f"wsoft:visibility:{light}")
            assert pv.GetAttr().GetTimeSamples() == [1.0, 13.0, 25.0], (mesh, light)
    deck = [primvar(composed, "/World/Static/BridgeDeck", "Sun", t)[0] for t in (1, 13, 25)]
    changed = [(deck[0] != d).sum() for d in deck[1:]]
    assert min(changed) > 10, changed
    box = [primvar(composed, "/World/Static/BoxA", "Sun", t)[0] for t in (1, 13, 25)]
    assert all(np.array_equal(box[0], b) for b in box[1:])
    assert stats["meshes"]["/World/Static/Ground"]["interpolation"] == "vertex"
    assert stats["meshes"]["/World/Static/BridgeDeck"]["interpolation"] == "faceVarying"


# -- textures ------------------------------------------------------------------------------------------


def test_texture_bake_and_its_hookup(tmp_path):
    """``texture_size=16``: an EXR per mesh with st and light whose texels are the visibility at
    their centre's 3-D point (the exact answer within 256 samples' error, sigma < 0.012), and in the
    layer a NodeGraph under the mesh with a UsdUVTexture reading it through a UsdPrimvarReader_float2
    of st, bound to no material; the occluder, without st, is warned about and keeps its primvar."""
    from pxr import Usd, UsdShade

    stage = parallel_stage(8, st=True)
    src = tmp_path / "src.usda"
    stage.GetRootLayer().Export(str(src))
    out = tmp_path / "bake" / "vis.usda"
    stats = {}
    wsoft.bake(str(src), "reference", samples=256, out=str(out), texture_size=16, device="cpu", stats=stats)
    exr = tmp_path / "bake" / "World_Ground_Light.exr"
    assert stats["textures"] == [str(exr)] and exr.exists()
    ch = read_exr(str(exr))
    assert set(ch) == {"V", "A"} and ch["V"].shape == (16, 16) and np.all(ch["A"] == 1.0)
    c = (np.arange(16) + 0.5) / 16
    x = -HALF + 2 * HALF * c[None, :]
    y = HALF - 2 * HALF * c[:, None]  # row 0 is t = 1
    exact = parallel_rect_exact(x, y, 3.0, 1.0, 1.0, 0.5)
    assert ((exact > 0.01) & (exact < 0.99)).sum() > 20
    assert np.abs(ch["V"] - exact).max() < 0.06
    assert any("/World/Occluder" in w and "st" in w for w in stats["warnings"])

    composed = Usd.Stage.Open(str(src))
    composed.GetRootLayer().subLayerPaths.append("bake/vis.usda")
    primvar(composed, "/World/Occluder")  # still baked
    ng = UsdShade.NodeGraph(composed.GetPrimAtPath("/World/Ground/wsoftVisibility"))
    assert ng
    tex = UsdShade.Shader(composed.GetPrimAtPath("/World/Ground/wsoftVisibility/Light"))
    assert tex.GetIdAttr().Get() == "UsdUVTexture"
    assert tex.GetInput("file").Get().resolvedPath == str(exr)
    src_st, _, _ = tex.GetInput("st").GetConnectedSource()
    reader = UsdShade.Shader(src_st.GetPrim())
    assert reader.GetIdAttr().Get() == "UsdPrimvarReader_float2" and reader.GetInput("varname").Get() == "st"
    out_src, out_name, _ = ng.GetOutput("Light").GetConnectedSource()
    assert out_src.GetPath() == tex.GetPath() and out_name == "r"
    assert not UsdShade.MaterialBindingAPI(composed.GetPrimAtPath("/World/Ground")).GetDirectBindingRel()


def test_texel_coverage_and_the_fill_of_uncovered_texels():
    """One triangle over the lower-left half of uv: the texels whose centre it covers, first
    triangle wins on overlap, and uncovered texels take the nearest covered texel's value."""
    tri = np.array([[[0, 0], [1, 0], [0, 1]]], np.float32)
    texel, t, bary = texel_coverage(np.concatenate([tri, tri]), 8)
    rows, cols = texel // 8, texel % 8
    s, tt = (cols + 0.5) / 8, 1 - (rows + 0.5) / 8
    assert len(texel) == 36 and np.all(s + tt <= 1.0) and np.all(t == 0)
    np.testing.assert_allclose(bary.sum(axis=1), 1.0)
    values = np.zeros((8, 8), np.float32)
    covered = np.zeros((8, 8), bool)
    covered[rows, cols] = True
    values[rows, cols] = (rows * 8 + cols).astype(np.float32)
    filled = fill_from_nearest(values, covered)
    for y, x in zip(*np.nonzero(~covered)):
        d2 = (rows - y) ** 2 + (cols - x) ** 2
        assert (filled[y, x] == values[rows, cols][d2 == d2.min()]).any()
    assert np.array_equal(filled[covered], values[covered])
    assert np.all(fill_from_nearest(values, np.zeros_like(covered)) == 1.0)


# -- the command line ------------------------------------------------------------------------------------


def run(*args):
    return wsoft_cli("bake", *args, cwd=ROOT)


@pytest.mark.parametrize("args,needle", [
    (["-t", "nope"], "unknown technique 'nope'"),
    (["-t", "izb"], "izb cannot bake: aa=adaptive"),
    (["-t", "hard", "--frames", "1-3"], "--frames '1-3' is not a:b"),
    (["-t", "hard", "--frames", "3:1"], "the last time code 1 is before the first 3"),
    (["-t", "hard", "--frames", "1:3:0"], "the step must be > 0"),
    (["-t", "hard", "--frames", "0:100"], "lightmapped_bridge.usda: frames 0..100 lie outside the stage's time range [1, 48]"),
    (["-t", "hard", "--texture-size", "0"], "--texture-size 0 out of range"),
    (["-t", "hard", "--light", "Nope"], "no shadow-casting light 'Nope'"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, needle):
    p = run("lightmapped_bridge", *args, "--out", str(tmp_path / "v.usda"))
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wsoft: error:") and needle in lines[0], p.stderr
    assert "Traceback" not in p.stderr and not (tmp_path / "v.usda").exists()


@pytest.mark.parametrize("out,needle", [("dir", "is a directory"), ("file/v.usda", "is not a directory"), ("v.exr", "must be a .usda")])
def test_an_unwritable_out_is_refused_before_baking(tmp_path, out, needle):
    (tmp_path / "dir").mkdir()
    (tmp_path / "file").write_text("x")
    p = run("lightmapped_bridge", "-t", "hard", "--out", str(tmp_path / out))
    assert p.returncode == 2 and needle in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr


def test_the_command_line_bakes_and_warns_about_meshes_without_st(tmp_path):
    out = tmp_path / "v.usda"
    p = run(scene_path("box_plane.usda"), "-t", "hard", "--texture-size", "4", "--out", str(out), "--device", "cpu")
    assert p.returncode == 0, p.stderr
    assert "no usable st primvar" in p.stderr and "s per frame" in p.stdout and f"wrote {out}" in p.stdout
    assert out.exists() and "Traceback" not in p.stderr


def test_bake_arguments_are_checked_without_warp_or_usd():
    """``wsoft bake --help`` and a malformed ``--frames`` answer before Warp or USD are imported."""
    code = ("import sys\nimport wsoft.cli\n"
            "for argv in ([\"bake\", \"--help\"], [\"bake\", \"x.usda\", \"-t\", \"hard\", \"--frames\", \"1-3\", \"--out\", \"o.usda\"]):\n"
            "    try:\n        print('exit', wsoft.cli.main(argv))\n    except SystemExit as exc:\n        print('exit', exc.code)\n"
            "print('loaded:', sorted(m for m in ('warp', 'pxr') if m in sys.modules))\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "exit 0" in p.stdout and "exit 2" in p.stdout and "loaded: []" in p.stdout
    assert "--texture-size" in p.stdout and "--frames '1-3' is not a:b" in p.stderr
