"""Cube maps for lights that surround their receivers (wsoft.lightspace.cube): the faces' answers
against the ray-traced one, seams, a light on a face boundary, a receiver at the light's centre,
the decision and what plan and the counters say."""

from __future__ import annotations

import numpy as np
import pytest

import wsoft
from wsoft.lightspace.cube import CUBE_THRESHOLD_DEG, FACE_NAMES, cube_decision, face_axes, owner_faces
from wsoft.stages.builders import add_box, add_camera, add_mesh, add_point_light, add_quad, add_sphere_light, make_stage
from wsoft.stages.mesh import quad_mesh
from wsoft.techniques import TECHNIQUES

SMALL = {"shadow_map_size": 256}


def _square(st, path: str, centre, half: float, axis: str) -> None:
    """A double-sided square of half-side ``half`` about ``centre``, perpendicular to ``axis`` (x, y or z)."""
    i = "xyz".index(axis)
    u, v = (i + 1) % 3, (i + 2) % 3
    pts = []
    for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        p = list(map(float, centre))
        p[u] += a * half
        p[v] += b * half
        pts.append(tuple(p))
    add_mesh(st, path, quad_mesh(pts), True, minimal=True)


def _closed_box(folder, name: str, cam_eye, cam_target, light: str = "point", light_pos=(0.0, 0.0, 0.0), occluders=None,
                extra=None) -> str:
    """A closed box [-2, 2]^3 around a light at ``light_pos``, one small square occluder 0.5 from each
    wall (or ``occluders``: (centre, half, normal axis) triples), a camera inside."""
    from pxr import Gf, UsdGeom

    st = make_stage()
    for i, axis in enumerate("xyz"):  # the walls, double-sided
        for sgn in (1, -1):
            _square(st, f"/World/Wall{axis}{'p' if sgn > 0 else 'n'}", tuple(2.0 * sgn if a == i else 0.0 for a in range(3)), 2.0, axis)
    occ = occluders if occluders is not None else [(tuple(s * 1.5 if a == i else 0.0 for a in range(3)), 0.3, "xyz"[i])
                                                   for i in range(3) for s in (1, -1)]
    for n, (c, half, axis) in enumerate(occ):
        _square(st, f"/World/Occ{n}", tuple(c), half, axis)
    if light == "point":
        add_point_light(st, "/World/Light", light_pos)
    else:
        add_sphere_light(st, "/World/Light", light_pos, 0.1)
    if extra is not None:
        extra(st)
    add_camera(st, "/World/Cam", cam_eye, cam_target, focal=9.0)
    path = str(folder / f"{name}.usda")
    st.GetRootLayer().Export(path)
    return path


def _disagree(a, b, cov) -> float:
    return float(np.mean(np.abs(a[cov] - b[cov]) > 0.5))


def test_owner_faces_and_axes():
    """Each direction belongs to the face of its dominant axis; each face's axes are right-handed and
    look along that axis."""
    d = np.array([[1, 0.2, -0.3], [-2, 1, 1], [0.1, 3, 0], [0, -1, 0.5], [0.2, 0.1, 5], [0, 0, -1]], float)
    assert list(owner_faces(d)) == [0, 1, 2, 3, 4, 5]
    for k in range(6):
        a = face_axes(np.eye(3), k)
        assert np.isclose(np.linalg.det(a), 1.0)
        assert owner_faces(a[:, 2][None])[0] == k


@pytest.mark.parametrize("corner", [(1, 1, 1), (-1, -1, -1)])
def test_point_light_in_closed_box_hard_equals_the_exact_answer(tmp_path, corner):
    """A point light at the centre of a closed box, an occluder near each wall: ``hard`` on the cube map
    gives the reference's one-sample answer on every wall (knife edges aside); two cameras looking
    into opposite corners see all six walls."""
    c = np.array(corner, float)
    path = _closed_box(tmp_path, "box", tuple(-0.3 * c), tuple(1.9 * c))
    hard = wsoft.render(path, "hard", width=64, height=64, shadow_map_size=512, cube="always")  # these walls lie within 75 degrees
    ref = wsoft.render(path, "reference", width=64, height=64, samples=1, jitter=False)
    cov = hard["A"] > 0
    assert cov.all()
    P = np.stack([hard["P.X"], hard["P.Y"], hard["P.Z"]], -1)[cov]
    walls = {(i, int(np.sign(P[k, i]))) for k in range(len(P)) for i in range(3) if abs(abs(P[k, i]) - 2.0) < 1e-3}
    assert len(walls) == 3  # this camera sees three walls; the other camera the other three
    assert 0.05 < ref.V[cov].mean() < 0.98  # the occluders' shadows are in view
    assert _disagree(hard.V, ref.V, cov) < 0.01
    c_ = hard.stats["counters"]["techniques"]["hard"]["Light"]
    drawn = set(c_["cube_faces"])
    seen = {FACE_NAMES[2 * i + (sg < 0)] for i, sg in walls}
    assert seen <= drawn and len(drawn) < 6  # the faces of the walls in view; a face with no receiver is not drawn
    assert c_["cube_texels"] == len(drawn) * 512 * 512
    assert not hard.stats["warnings"]


@pytest.mark.parametrize("technique", ["pcf", "pcss", "vsm", "esm", "evsm", "msm", "msm_soft", "vssm", "ssm", "essm", "salzman"])
def test_every_shadow_map_technique_runs_on_a_cube_map(tmp_path, technique):
    """Every technique with light views renders a sphere light in a closed box on a cube map, with no
    receiver left outside every map: close to the reference, no warning."""
    path = _closed_box(tmp_path, "box_sphere", (-0.3, -0.3, -0.3), (1.9, 1.9, 1.9), light="sphere")
    params = dict(TECHNIQUES[technique].quick_params, cube="always")  # the camera's three walls lie within 75 degrees
    params.setdefault("shadow_map_size", 256)
    f = wsoft.render(path, technique, width=48, height=48, **params)
    ref = wsoft.render(path, "reference", width=48, height=48, samples=64)
    cov = f["A"] > 0
    assert np.isfinite(f.V).all()
    assert "cube_faces" in f.stats["counters"]["techniques"][technique]["Light"]
    assert not [w for w in f.stats["warnings"] if "unshadowed" in w or "left lit" in w]
    assert float(np.abs(f.V[cov] - ref.V[cov]).mean()) < 0.08


def _ring_stage(folder, name: str, rotate_deg: float) -> str:
    """A sphere light 1 above a wide floor, a ring of posts around it whose shadows cross the cube's
    face edges on the floor (|x| = 1 and the diagonals |x| = |y|); the light's frame turned by
    ``rotate_deg`` about the vertical moves the edges, not the shadows."""
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/Floor", (0, 0, 0), 6)
    for n, ang in enumerate(np.arange(0, 360, 22.5)):
        a = np.radians(ang)
        add_box(st, f"/World/Post{n}", (1.3 * np.cos(a) - 0.08, 1.3 * np.sin(a) - 0.08, 0.0), (1.3 * np.cos(a) + 0.08, 1.3 * np.sin(a) + 0.08, 0.5))
    light = UsdLux.SphereLight.Define(st, "/World/Light")
    light.CreateRadiusAttr(0.25)
    x = UsdGeom.XformCommonAPI(light)
    x.SetTranslate(Gf.Vec3d(0, 0, 1))
    x.SetRotate(Gf.Vec3f(0, 0, rotate_deg))
    add_camera(st, "/World/Cam", (0, -0.01, 7), (0, 0, 0), focal=28.0)
    path = str(folder / f"{name}.usda")
    st.GetRootLayer().Export(path)
    return path


@pytest.mark.parametrize("technique,seams", [("pcf", {}), ("pcf", {"radius": 6.0, "seams": "lookup"}), ("pcss", {})])
def test_kernel_across_a_face_edge_matches_the_kernel_away_from_it(tmp_path, technique, seams):
    """The same shadows rendered with the cube's face edges in two places (the light's frame turned
    30 degrees): on the pixels near an edge in either, they differ no more than elsewhere, and the
    error against the reference near edges does not stand out (seam-correct filtering: guard bands,
    or pcf's taps read by direction from the neighbouring face)."""
    a = _ring_stage(tmp_path, "ring0", 0.0)
    b = _ring_stage(tmp_path, "ring30", 30.0)
    kw = dict(width=96, height=96, shadow_map_size=512, cube="always", **seams)
    fa = wsoft.render(a, technique, **kw)
    fb = wsoft.render(b, technique, **kw)
    ref = wsoft.render(a, "reference", width=96, height=96, samples=256)
    cov = fa["A"] > 0
    P = np.stack([fa["P.X"], fa["P.Y"], fa["P.Z"] - 1.0], -1)

    def near_edge(turn):
        c, s = np.cos(np.radians(turn)), np.sin(np.radians(turn))
        q = np.stack([c * P[..., 0] + s * P[..., 1], -s * P[..., 0] + c * P[..., 1], P[..., 2]], -1)
        aq = np.sort(np.abs(q), axis=-1)
        return (aq[..., 2] - aq[..., 1]) < 0.1 * aq[..., 2]  # within ~3 degrees of a face edge

    pen = cov & (ref.V > 0.02) & (ref.V < 0.98)
    edge = pen & (near_edge(0.0) | near_edge(30.0))
    away = pen & ~edge
    assert edge.sum() > 30 and away.sum() > 30, (edge.sum(), away.sum())  # penumbrae cross edges in this stage
    d_edge = float(np.abs(fa.V - fb.V)[edge].mean())
    d_away = float(np.abs(fa.V - fb.V)[away].mean())
    assert d_edge <= 1.5 * d_away + 0.005  # without a guard band: pcf 0.028 near edges vs 0.008 elsewhere
    e_edge = float(np.abs(fa.V - ref.V)[pen & near_edge(0.0)].mean())
    e_away = float(np.abs(fa.V - ref.V)[pen & ~near_edge(0.0)].mean())
    assert e_edge <= 1.3 * e_away + 0.01  # without a guard band: pcss 0.070 near edges vs 0.036 elsewhere


def test_pcf_seam_lookup_reads_the_neighbouring_face(tmp_path):
    """``seams=lookup`` (faces drawn with a 2-texel guard band; taps past an edge read the face their
    direction belongs to) gives the guard band's answer where an 8-texel kernel crosses a face edge:
    taps that stayed on their own face would read cleared texels there (mean |dV| 0.063 within 0.02 of
    an edge, against 0.002)."""
    a = _ring_stage(tmp_path, "ring0", 0.0)
    kw = dict(width=96, height=96, shadow_map_size=512, cube="always", radius=8.0)
    guard = wsoft.render(a, "pcf", **kw)
    look = wsoft.render(a, "pcf", seams="lookup", **kw)
    passes = look.stats["counters"]["passes"]
    assert any(k.startswith("light_depth[") and k.endswith("guard2") for k in passes), list(passes)
    cov = guard["A"] > 0
    aq = np.sort(np.abs(np.stack([guard["P.X"], guard["P.Y"], guard["P.Z"] - 1.0], -1)), axis=-1)
    edge = cov & ((aq[..., 2] - aq[..., 1]) < 0.02 * aq[..., 2])
    assert edge.sum() > 100
    assert float(np.abs(guard.V - look.V)[edge].mean()) < 0.02
    assert np.isfinite(look.V).all()
    with pytest.raises(wsoft.ParameterError, match="receiver_bias"):
        wsoft.render(a, "pcf", seams="lookup", receiver_bias="normal", width=8, height=8)
    with pytest.raises(wsoft.ParameterError, match="seams"):
        wsoft.render(a, "pcf", seams="sampler", width=8, height=8)


def test_light_exactly_on_a_face_boundary_direction(tmp_path):
    """Occluders centred on the directions where two or three faces meet (|x| = |y|, |x| = |y| = |z|):
    the hard shadow is the exact one."""
    def cubes(st):
        for n, c in enumerate([(1.0, 1.0, 0.0), (-1.0, 1.0, 0.0), (0.8, -0.8, -0.8)]):
            add_box(st, f"/World/Block{n}", tuple(x - 0.2 for x in c), tuple(x + 0.2 for x in c))

    for eye, target in [((-1.0, 1.8, 1.5), (2, 2, 0)), ((1.0, 1.8, 1.5), (-2, 2, 0)), ((-1.0, -1.8, 1.5), (2, -2, -2))]:
        path = _closed_box(tmp_path, "boundary", eye, target, occluders=[], extra=cubes)
        hard = wsoft.render(path, "hard", width=48, height=48, shadow_map_size=512, cube="always")
        ref = wsoft.render(path, "reference", width=48, height=48, samples=1, jitter=False)
        cov = hard["A"] > 0
        assert ref.V[cov].mean() < 0.995  # a shadow in view
        assert _disagree(hard.V, ref.V, cov) < 0.015


def test_receiver_at_the_lights_centre_warns_and_stays_finite(tmp_path):
    """A wall through a point light's centre, the camera's centre pixel on it: one warning line naming
    the light, finite V everywhere."""

    def wall(st):
        _square(st, "/World/Through", (0.0, 0.0, 0.0), 1.0, "y")

    path = _closed_box(tmp_path, "at_light", (0.0, -1.5, 0.0), (0.0, 0.0, 0.0), extra=wall)
    for tech in ("hard", "pcf", "vsm"):
        f = wsoft.render(path, tech, width=33, height=33, shadow_map_size=256)
        assert np.isfinite(f.V).all()
        hits = [w for w in f.stats["warnings"] if "at its centre" in w]
        assert len(hits) == 1 and "/World/Light" in hits[0] and "\n" not in hits[0]


def test_decision_threshold_and_modes(tmp_path):
    """Receivers within 75 degrees of one axis: one frustum; all around: a cube map of the faces that hold
    receivers; cube=never keeps one frustum (and its warning), cube=always draws a cube anyway."""
    from wsoft.scene.types import LIGHT_SPHERE, Light

    light = Light(path="/L", kind=LIGHT_SPHERE, position=np.zeros(3), frame=np.eye(3), radius=0.1)
    ang = np.radians(np.linspace(-50, 50, 11))
    narrow = np.stack([np.tan(ang), np.zeros_like(ang), -np.ones_like(ang)], -1)  # below the light, within 50 degrees
    d = cube_decision(light, narrow, "test")
    assert d.half_angle < CUBE_THRESHOLD_DEG and not d.cube("auto") and d.cube("always") and not d.cube("never")
    wide = np.concatenate([narrow, [[3.0, 0.0, -1.0], [0.0, 0.0, 1.0]]])
    d = cube_decision(light, wide, "test")
    assert d.cube("auto") and d.half_angle == 180.0
    assert set(d.faces) >= {0, 4, 5}
    from wsoft.stages.adversarial import b_lamp_sphere

    path = b_lamp_sphere(str(tmp_path))  # a sphere light in a closed box over a ground, seen from outside
    never = wsoft.render(path, "hard", width=32, height=32, shadow_map_size=256, cube="never")
    assert any("single-frustum" in w for w in never.stats["warnings"])
    assert "cube_faces" not in never.stats["counters"]["techniques"].get("hard", {}).get("Light", {})
    auto = wsoft.render(path, "hard", width=32, height=32, shadow_map_size=256)
    assert not auto.stats["warnings"] and auto.V[auto["A"] > 0].mean() < 0.01  # the reference's answer: all in shadow
    with pytest.raises(wsoft.errors.ParameterError):
        wsoft.render(path, "hard", width=32, height=32, cube="sometimes")


def test_plan_says_which_lights_get_a_cube_map(tmp_path):
    """plan names the light's views (a cube map, its faces, why); izb, which has no cube map, refuses a
    light no frustum of at most 80 degrees holds, saying why."""
    from wsoft.stages.adversarial import b_lamp_sphere

    p = wsoft.plan(b_lamp_sphere(str(tmp_path)), ["hard", "izb"])
    assert p["light_views"]["/World/Light"].startswith("cube map, ")
    assert any("cube_select" in x for x in p["techniques"]["hard"])
    assert "cube map" in p["not_applicable"]["izb"][0]["reason"]


# -- dual-paraboloid maps (omni=paraboloid) -----------------------------------------------------------


@pytest.mark.parametrize("corner", [(1, 1, 1), (-1, -1, -1)])
def test_dual_paraboloid_hard_equals_the_exact_answer_on_every_wall(tmp_path, corner):
    """``hard`` with ``omni=paraboloid`` in the closed box: the reference's one-sample answer on all six
    walls (the two cameras), from the hemispheres that hold receivers, no warning."""
    from wsoft.lightspace.cube import guard_window

    c = np.array(corner, float)
    path = _closed_box(tmp_path, "box", tuple(-0.3 * c), tuple(1.9 * c))
    hard = wsoft.render(path, "hard", width=64, height=64, shadow_map_size=512, cube="always", omni="paraboloid")
    ref = wsoft.render(path, "reference", width=64, height=64, samples=1, jitter=False)
    cov = hard["A"] > 0
    assert 0.05 < ref.V[cov].mean() < 0.98
    assert _disagree(hard.V, ref.V, cov) < 0.01
    c_ = hard.stats["counters"]["techniques"]["hard"]["Light"]
    assert "cube_faces" not in c_ and c_["paraboloid_texels"] == len(c_["paraboloid_hemispheres"]) * 512 * 512
    p = next(v for k, v in hard.stats["counters"]["passes"].items() if k.startswith("paraboloid["))
    assert sum(p["receivers_per_hemisphere"].values()) == int(cov.sum())
    assert p["window_radius"] == pytest.approx(guard_window(2.0, 512))
    assert not hard.stats["warnings"]


def test_dual_paraboloid_pcf_across_the_equator(tmp_path):
    """``pcf`` on a dual-paraboloid map of a sphere light in the closed box, the paraboloids' axis along
    z and then turned 60 degrees: close to the reference, and the two answers differ on pixels near
    either equator no more than elsewhere (the guard band past the equator)."""
    from pxr import Gf, UsdGeom

    def turned(st):
        UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/Light")).SetRotate(Gf.Vec3f(60.0, 0.0, 0.0))

    kw = dict(width=64, height=64, shadow_map_size=256, cube="always", omni="paraboloid")
    a = _closed_box(tmp_path, "eq0", (-0.3, -0.3, -0.3), (1.9, 1.9, 1.9), light="sphere")
    b = _closed_box(tmp_path, "eq60", (-0.3, -0.3, -0.3), (1.9, 1.9, 1.9), light="sphere", extra=turned)
    fa, fb = wsoft.render(a, "pcf", **kw), wsoft.render(b, "pcf", **kw)
    ref = wsoft.render(a, "reference", width=64, height=64, samples=64)
    cov = fa["A"] > 0
    assert np.isfinite(fa.V).all() and float(np.abs(fa.V[cov] - ref.V[cov]).mean()) < 0.08
    P = np.stack([fa["P.X"], fa["P.Y"], fa["P.Z"]], -1)
    t = np.radians(60.0)
    axis_b = np.array([0.0, -np.sin(t), np.cos(t)])  # the turned light's z axis
    n = np.linalg.norm(P, axis=-1)

    def near_equator(axis):
        return np.abs(P @ axis) < 0.08 * n

    near = cov & (near_equator(np.array([0.0, 0.0, 1.0])) | near_equator(axis_b))
    assert near.sum() > 50 and (cov & ~near).sum() > 50
    d = np.abs(fa.V - fb.V)
    assert float(d[near].mean()) <= 1.5 * float(d[cov & ~near].mean()) + 0.01


def test_dual_paraboloid_bad_inputs_and_the_light_centre(tmp_path):
    """``omni`` takes cube or paraboloid; a technique without it rejects the key; a receiver at the
    light's centre gives one warning line and finite V."""
    from wsoft.errors import ParameterError

    def wall(st):
        _square(st, "/World/Through", (0.0, 0.0, 0.0), 1.0, "y")

    path = _closed_box(tmp_path, "at_light_dp", (0.0, -1.5, 0.0), (0.0, 0.0, 0.0), extra=wall)
    with pytest.raises(ParameterError, match="omni"):
        wsoft.render(path, "hard", width=8, height=8, omni="sphere")
    with pytest.raises(ParameterError, match="omni"):
        wsoft.render(path, "pcss", width=8, height=8, omni="paraboloid")
    f = wsoft.render(path, "pcf", width=33, height=33, shadow_map_size=256, omni="paraboloid")
    assert np.isfinite(f.V).all()
    hits = [w for w in f.stats["warnings"] if "at its centre" in w]
    assert len(hits) == 1 and "/World/Light" in hits[0] and "\n" not in hits[0]
    assert "paraboloid_hemispheres" in f.stats["counters"]["techniques"]["pcf"]["Light"]
