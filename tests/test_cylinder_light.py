"""UsdLux CylinderLight: loading, the reference against closed forms, and every technique on it.

A cylinder light is seen from a point as its silhouette rectangle (:func:`wsoft.lightspace.light.silhouette_rect`):
as long as the cylinder, between the lines where the planes through the point tangent to its side
touch it. The reference samples that rectangle, so an occluder whose edge runs along the light's
axis hides a part of it that follows from the cross-section alone, and a wall across the axis
hides exactly the part of the light beyond it: both closed forms are checked per pixel."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import add_box, add_camera, add_quad, make_stage, wsoft_cli, skip_if_no_local_lights

import wsoft
from wsoft.errors import SceneError
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_POINT
from wsoft.stages import add_cylinder_light
from wsoft.techniques import TECHNIQUES

H_LIGHT, RADIUS, H_OCC, EDGE = 2.0, 0.6, 1.0, 0.2  # the light's height and radius, the half-plane's height and edge (y)


def _quad(stage, path, pts):
    from pxr import UsdGeom

    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(pts)
    m.CreateFaceVertexCountsAttr([4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    m.CreateDoubleSidedAttr(True)
    return m


def across_stage(line: bool = False):
    """A fat cylinder light along X (length 4, radius 0.6) at height 2 over the ground, and between
    them the half-plane z = 1, y >= 0.2 (its edge along the light's axis); the camera below it
    sees the ground across the penumbra."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 6)
    _quad(st, "/World/Occluder", [(-20, EDGE, H_OCC), (20, EDGE, H_OCC), (20, 20, H_OCC), (-20, 20, H_OCC)])
    add_cylinder_light(st, "/World/Tube", (0, 0, H_LIGHT), 4.0, RADIUS, treat_as_line=True if line else None)
    add_camera(st, "/World/Cam", (0, 0.4, 0.8), (0, 0.4, 0), up=(0, 1, 0), focal=7)
    return st


def across_exact(py: np.ndarray, radius: float) -> np.ndarray:
    """The visible fraction of the silhouette rectangle from ground points at ``y = py`` under
    :func:`across_stage`'s half-plane: in the cross-section x = const the rectangle is the chord
    ``C + v t`` (``|t| <= w``) between the tangent points seen from ``(py, 0)``; a ray to ``C + v t``
    crosses z = 1 at y < 0.2 (visible) where a linear function of ``t`` is negative. A line light
    (radius 0): 1 or 0, whether the ray to its axis passes the edge."""
    qy, qz = py, -H_LIGHT + 0.0 * py
    rho = np.hypot(qy, qz)
    rr = radius * radius / rho
    cy, cz = qy / rho * rr, H_LIGHT + qz / rho * rr  # the chord's centre
    vy, vz = -qz / rho, qy / rho  # along it
    w = radius * np.sqrt(np.maximum(1.0 - rr / rho, 0.0))
    f0 = (cy - py) * H_OCC - (EDGE - py) * cz
    f1 = vy * H_OCC - (EDGE - py) * vz
    if radius == 0.0:
        return (f0 < 0.0).astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -f0 / f1  # f(t) = f0 + f1 t = 0
        frac = np.where(f1 > 0.0, (t + w) / (2 * w), (w - t) / (2 * w))  # f < 0 below t (f1 > 0) or above it
    frac = np.where(np.abs(f1) < 1e-12, (f0 < 0.0).astype(float), frac)
    return np.clip(frac, 0.0, 1.0)


def test_the_reference_matches_the_closed_form_of_an_edge_along_the_axis(device):
    f = wsoft.render(wsoft.load_scene(across_stage()), "reference", width=24, height=24, device=device, samples=256)
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    exact = across_exact(f["P.Y"], RADIUS)
    v, se = f["V"][g], f["V_stderr"][g]
    err = v - exact[g]
    pen = (exact[g] > 0.02) & (exact[g] < 0.98)
    assert pen.sum() > 150 and (exact[g] == 1.0).any() and (exact[g] == 0.0).any()  # penumbra, lit and umbra all in view
    assert np.all(np.abs(err) <= 3 * se + 0.01), np.abs(err).max()
    assert np.abs(err[pen]).mean() < 0.01
    assert abs(err[pen].mean()) < 3 * np.sqrt((se[pen] ** 2).sum()) / pen.sum()  # unbiased


def test_a_line_light_under_an_edge_along_its_axis_is_all_or_nothing(device):
    scene = wsoft.load_scene(across_stage(line=True))
    assert scene.lights[0].is_line
    f = wsoft.render(scene, "reference", width=24, height=24, device=device, samples=16)
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    exact = across_exact(f["P.Y"], 0.0)
    assert set(np.unique(f["V"][g])) == {0.0, 1.0}
    assert (f["V"][g] == exact[g]).mean() > 0.98  # a pixel may straddle the edge's hard shadow


WALL = 0.3  # the wall's plane x = 0.3 cuts the light (length 2 along X) at 65% of its length


@pytest.mark.parametrize("line", [False, True], ids=["cylinder", "line"])
def test_a_wall_across_the_axis_hides_exactly_the_light_beyond_it(device, line):
    """The wall x = 0.3 (higher than the light) leaves a point before it the light's 65% before the
    wall and a point past it the other 35%, whatever its radius: the rectangle spans the cylinder's
    whole length."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    _quad(st, "/World/Wall", [(WALL, -20, -0.5), (WALL, 20, -0.5), (WALL, 20, 4.0), (WALL, -20, 4.0)])
    add_cylinder_light(st, "/World/Tube", (0, 0, 3), 2.0, 0.2, treat_as_line=True if line else None)
    add_camera(st, "/World/Cam", (WALL, 0.0, 8.0), (WALL, 0.0, 0.0), up=(0, 1, 0), focal=30)
    f = wsoft.render(wsoft.load_scene(st), "reference", width=16, height=16, device=device, samples=256)
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3) & (np.abs(f["P.X"] - WALL) > 0.05)
    before = g & (f["P.X"] < WALL)
    past = g & (f["P.X"] > WALL)
    assert before.sum() > 50 and past.sum() > 50
    for mask, exact in ((before, 0.5 * (1.0 + WALL)), (past, 0.5 * (1.0 - WALL))):
        v = f["V"][mask]
        assert np.all(np.abs(v - exact) < 0.04), (exact, v.min(), v.max())
        assert abs(v.mean() - exact) < 0.005, (exact, v.mean())


# --------------------------------------------------------------------------- loading


def _load_one(**authored):
    """A stage with one CylinderLight (``authored``: length, radius, treat_as_line, scale,
    rotate) loaded: (its light or None, the load warnings)."""
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    lt = UsdLux.CylinderLight.Define(st, "/World/Tube")
    if "length" in authored:
        lt.CreateLengthAttr(authored["length"])
    if "radius" in authored:
        lt.CreateRadiusAttr(authored["radius"])
    if "treat_as_line" in authored:
        lt.CreateTreatAsLineAttr(authored["treat_as_line"])
    xf = UsdGeom.XformCommonAPI(lt.GetPrim())
    xf.SetTranslate(Gf.Vec3d(0, 0, 3))
    if "rotate" in authored:
        xf.SetRotate(Gf.Vec3f(*authored["rotate"]))
    if "scale" in authored:
        xf.SetScale(Gf.Vec3f(*authored["scale"]))
    scene = wsoft.load_scene(st)
    return (scene.lights[0] if scene.lights else None), scene.warnings


def test_defaults_scaling_and_the_axis():
    light, warnings = _load_one()
    assert light.kind == LIGHT_CYLINDER and light.kind_name == "cylinder" and not warnings
    assert light.half_size == pytest.approx((0.5, 0.5)) and light.radius == pytest.approx(0.5)  # UsdLux defaults: length 1, radius 0.5
    assert not light.one_sided and not light.is_line and light.extent() == pytest.approx(np.hypot(0.5, 0.5))
    assert light.size_description() == "length 1, radius 0.5"
    light, warnings = _load_one(length=2.0, radius=0.1, scale=(3.0, 2.0, 2.0), rotate=(0, 0, 90))
    assert light.half_size == pytest.approx((3.0, 0.2)) and light.radius == pytest.approx(0.2) and not warnings
    assert np.allclose(light.frame[:, 0], [0, 1, 0], atol=1e-6)  # the axis: where the transform takes local X


def test_unequal_scale_across_the_axis_is_rendered_round_and_said():
    light, warnings = _load_one(length=2.0, radius=0.1, scale=(1.0, 1.0, 3.0))
    assert light.radius == pytest.approx(0.2)
    assert len(warnings) == 1 and "/World/Tube" in warnings[0] and "mean radius 0.2" in warnings[0]


def test_a_line_light_from_treat_as_line_or_radius_0():
    light, warnings = _load_one(length=2.0, radius=0.3, treat_as_line=True)
    assert light.kind == LIGHT_CYLINDER and light.is_line and light.half_size == (pytest.approx(1.0), 0.0) and not warnings
    assert light.size_description() == "line, length 2"
    light, warnings = _load_one(length=2.0, radius=0.0)
    assert light.is_line and len(warnings) == 1 and "radius 0: rendered as a line light" in warnings[0]


def test_length_0_is_a_point_light_with_a_warning():
    light, warnings = _load_one(length=0.0, radius=0.3)
    assert light.kind == LIGHT_POINT
    assert len(warnings) == 1 and "/World/Tube" in warnings[0] and "length 0" in warnings[0]


@pytest.mark.parametrize("attr", ["length", "radius"])
def test_a_negative_size_is_a_one_line_error_naming_the_prim(tmp_path, attr):
    with pytest.raises(SceneError, match=rf"/World/Tube.*inputs:{attr} = -1 is negative"):
        _load_one(**{attr: -1.0})
    path = tmp_path / "bad.usda"
    path.write_text('#usda 1.0\n(\n    upAxis = "Z"\n)\ndef Mesh "G"\n{\n    point3f[] points = [(0,0,0),(1,0,0),(0,1,0)]\n'
                    '    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 2]\n}\n'
                    f'def CylinderLight "Tube"\n{{\n    float inputs:{attr} = -1\n}}\n')
    p = wsoft_cli("plan", str(path))
    assert p.returncode == 2 and "Traceback" not in p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("wsoft: error")]
    assert len(lines) == 1 and "/Tube" in lines[0] and f"inputs:{attr}" in lines[0] and str(path) in lines[0], p.stderr


def test_plan_and_techniques_show_it(tmp_path):
    path = tmp_path / "tube.usda"
    st = across_stage()
    st.Export(str(path))
    p = wsoft_cli("plan", str(path), "-t", "pcss", "-t", "pwedge")
    assert p.returncode == 0, p.stderr
    assert "/World/Tube" in p.stdout and "cylinder" in p.stdout and f"length 4, radius {RADIUS:g}" in p.stdout
    assert "emits: all around" in p.stdout
    assert "pcss: cylinder light /World/Tube: its bound seen along the light view's axis" in p.stdout
    assert "pwedge: cylinder light /World/Tube: its silhouette rectangle" in p.stdout
    j = json.loads(wsoft_cli("plan", str(path), "-t", "hard", "--json").stdout)
    assert j["lights"][0]["kind"] == "cylinder" and j["cylinder_lights"]["hard"][0]["light"] == "/World/Tube"
    t = wsoft_cli("techniques")
    assert t.returncode == 0 and t.stdout.count("  cylinder light: ") == len(TECHNIQUES)


# --------------------------------------------------------------------------- every technique


def _box_stage(line: bool = False):
    """A 0.8 x 0.8 box at z 0.8..1 over the ground, a cylinder light (length 2, radius 0.15)
    along X beside it at height 3, seen obliquely."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    add_box(st, "/World/Box", (-0.4, -0.4, 0.8), (0.4, 0.4, 1.0))
    add_cylinder_light(st, "/World/Tube", (0, -0.8, 3), 2.0, 0.15, treat_as_line=True if line else None)
    add_camera(st, "/World/Cam", (0, -2.5, 4), (0, 0.5, 0), focal=24)
    return st


@pytest.fixture(scope="module")
def box_scenes():
    """(scene, its 256-sample reference) for the cylinder and the line light."""
    out = {}
    for line in (False, True):
        scene = wsoft.load_scene(_box_stage(line))
        out[line] = scene, wsoft.render(scene, "reference", width=48, height=36, device="cpu", samples=256)
    return out


EXACT = {"pwedge": 0.003, "dcs": 0.015}  # sample or integrate the reference's rectangle: ground MAE at most this


@pytest.mark.parametrize("line", [False, True], ids=["cylinder", "line"])
@pytest.mark.parametrize("technique", sorted(n for n in TECHNIQUES if n != "reference"))
def test_every_technique_renders_it_finite_with_its_shadow_in_place(box_scenes, technique, line):
    """Finite, in [0, 1], with an umbra; around the box, where V < 1/2 overlaps the reference's by
    at least half and the mean error is that of a shadow of the right size in the right place."""
    skip_if_no_local_lights(technique)
    scene, ref = box_scenes[line]
    cls = TECHNIQUES[technique]
    if cls.cylinder_model.startswith("none"):  # declined with its reason, never left lit
        light = scene.lights[0]
        why = cls(cls.make_params(dict(cls.quick_params))).supports(scene, light)
        assert why, f"{technique} says it declines cylinder lights but supports {light.path}"
        pytest.skip(f"{technique} declines a cylinder light: {why}")
    p = dict(cls.quick_params)
    if cls.size_param:
        p[cls.size_param] = 256
    if technique == "rtdenoise":  # its quick single sample's overlap swings 0.47-0.69 over seeds here; 4 samples: 0.73-0.83
        p["samples"] = 4
    f = wsoft.render(scene, technique, width=48, height=36, device="cpu", **p)
    v, r = f["V"], ref["V"]
    g = (ref["A"] > 0) & (np.abs(ref["P.Z"]) < 1e-3)
    assert np.all(np.isfinite(v)) and v.min() >= 0.0 and v.max() <= 1.0
    near = g & (np.abs(ref["P.X"]) < 1.6) & (ref["P.Y"] > -1.0) & (ref["P.Y"] < 1.6)
    assert (r[near] < 0.05).sum() > 10 and (v[near] < 0.05).sum() > 5  # an umbra in both
    a, b = v[near] < 0.5, r[near] < 0.5
    assert (a & b).sum() / (a | b).sum() > 0.5
    assert np.abs(v - r)[near].mean() < 0.1
    if technique in EXACT:
        assert np.abs(v - r)[g].mean() < EXACT[technique]
