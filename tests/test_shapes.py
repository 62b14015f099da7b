"""UsdGeom's own shapes (wsoft.scene.shapes): each casts the shadow of its mesh equivalent, built
independently here; extents against USD's own; the silhouette bound; instancing; bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import add_box, add_camera, add_quad, add_rect_light, make_stage, wsoft_cli
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

import wsoft
from wsoft.errors import SceneError
from wsoft.scene.shapes import SEGMENTS_CURVED, SEGMENTS_FLAT, SHAPE_TOLERANCE
from wsoft.stages.builders import add_instance, add_material, bind, set_display_color

W, H, SAMPLES, SEED = 64, 48, 32, 7
CENTRE = (0.0, 0.0, 1.0)  # where each occluder sits, above the ground under the light


# --------------------------------------------------------------------------- meshes built here


def _mesh(st, path: str, pts, faces, at=CENTRE) -> UsdGeom.Mesh:
    m = UsdGeom.Mesh.Define(st, path)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts, np.float32)))
    m.CreateFaceVertexCountsAttr(Vt.IntArray([len(f) for f in faces]))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for f in faces for i in f]))
    UsdGeom.XformCommonAPI(m).SetTranslate(Gf.Vec3d(*at))
    return m


def _icosphere(radius: float, centre=(0.0, 0.0, 0.0), levels: int = 5):
    """An icosahedron subdivided ``levels`` times, its points pushed onto the sphere (20 * 4^levels faces)."""
    t = (1 + math.sqrt(5)) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1),
         (-t, 0, -1), (-t, 0, 1)]
    pts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
             (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(levels):
        mid: dict[tuple[int, int], int] = {}

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                p = pts[a] + pts[b]
                pts.append(p / np.linalg.norm(p))
                mid[k] = len(pts) - 1
            return mid[k]

        faces = [f for a, b, c in faces for f in ((a, m(a, b), m(c, a)), (b, m(b, c), m(a, b)), (c, m(c, a), m(b, c)),
                                                  (m(a, b), m(b, c), m(c, a)))]
    return np.array(pts) * radius + np.asarray(centre), faces


def _frustum(r_bottom: float, r_top: float, height: float, n: int = 256):
    """A closed conical frustum along +z (an n-gon at each end; an apex where a radius is 0)."""
    t = 2 * np.pi * np.arange(n) / n
    ring = lambda r, z: np.stack([r * np.cos(t), r * np.sin(t), np.full(n, z)], axis=1)  # noqa: E731
    if r_top == 0:
        pts = np.concatenate([ring(r_bottom, -height / 2), [[0, 0, height / 2]]])
        return pts, [list(range(n))[::-1]] + [(i, (i + 1) % n, n) for i in range(n)]
    pts = np.concatenate([ring(r_bottom, -height / 2), ring(r_top, height / 2)])
    side = [(i, (i + 1) % n, n + (i + 1) % n, n + i) for i in range(n)]
    return pts, [list(range(n))[::-1], list(range(n, 2 * n))] + side


def _union(*parts):
    pts, faces, off = [], [], 0
    for p, f in parts:
        pts.append(p)
        faces += [[i + off for i in face] for face in f]
        off += len(p)
    return np.concatenate(pts), faces


def _capsule_1_spheres(rb: float, rt: float, h: float):
    """The end spheres of a Capsule_1 (tangent to its frustum at +-h/2): (radius, centre z) bottom, top."""
    slope = (rb - rt) / h if h > 0 else 0.0
    sec = math.sqrt(1 + slope * slope)
    return (rb * sec, -h / 2 - slope * rb), (rt * sec, h / 2 - slope * rt)


# shape, its attributes, the same solid as meshes (a union of closed meshes casts the union's shadow)
CASES = {
    "Cube": ({"size": 0.8}, lambda: None),
    "Sphere": ({"radius": 0.5}, lambda: [_icosphere(0.5)]),
    "Cylinder": ({"radius": 0.4, "height": 0.9}, lambda: [_frustum(0.4, 0.4, 0.9)]),
    "Cone": ({"radius": 0.5, "height": 0.9}, lambda: [_frustum(0.5, 0.0, 0.9)]),
    "Capsule": ({"radius": 0.3, "height": 0.6},
                lambda: [_frustum(0.3, 0.3, 0.6), _icosphere(0.3, (0, 0, -0.3)), _icosphere(0.3, (0, 0, 0.3))]),
    "Cylinder_1": ({"radiusBottom": 0.5, "radiusTop": 0.2, "height": 0.9}, lambda: [_frustum(0.5, 0.2, 0.9)]),
    "Capsule_1": ({"radiusBottom": 0.4, "radiusTop": 0.15, "height": 0.6},
                  lambda: [_frustum(0.4, 0.15, 0.6)] + [_icosphere(r, (0, 0, c)) for r, c in _capsule_1_spheres(0.4, 0.15, 0.6)]),
}


def _define(st, kind: str, path: str, attrs: dict, at=CENTRE, axis: str | None = None):
    shape = getattr(UsdGeom, kind).Define(st, path)
    for name, v in attrs.items():
        getattr(shape, f"Create{name[0].upper()}{name[1:]}Attr")(v)
    if axis is not None:
        shape.CreateAxisAttr(axis)
    UsdGeom.XformCommonAPI(shape).SetTranslate(Gf.Vec3d(*at))
    return shape


def _stage():
    """A ground quad under a rect light to one side, seen from the other side: the shadow falls
    clear of the occluder at CENTRE."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    add_rect_light(st, "/World/Light", (2.0, 0, 3.0), 1, 1)
    add_camera(st, "/World/Cam", (-1.5, -5, 6), (-1.0, 0, 0), focal=20)
    return st


def _v(st, device):
    scene = wsoft.load_scene(st)
    f = wsoft.render(scene, "reference", width=W, height=H, device=device, samples=SAMPLES, seed=SEED)
    return scene, f


# --------------------------------------------------------------------------- each shape against its mesh


@pytest.mark.parametrize("kind", [k for k in CASES if hasattr(UsdGeom, k)])
def test_shape_casts_the_shadow_of_its_mesh(device, kind):
    attrs, meshes = CASES[kind]
    a = _stage()
    _define(a, kind, "/World/Shape", attrs)
    b = _stage()
    if kind == "Cube":
        s = attrs["size"] / 2
        add_box(b, "/World/Shape", (-s, -s, 1 - s), (s, s, 1 + s))  # 8 points, 6 quads
    else:
        for i, (p, f) in enumerate(meshes()):
            _mesh(b, f"/World/Shape{i}", p, f)
    sa, fa = _v(a, device)
    sb, fb = _v(b, device)
    assert not any("ignored" in w for w in sa.warnings), sa.warnings
    assert sa.prims == ["/World/Ground", "/World/Shape"] and np.all(sa.tri_closed[sa.tri_prim == 1] == 1)
    cov = (fa["A"] > 0) & (fb["A"] > 0)
    va, vb = fa["V"][cov], fb["V"][cov]
    assert (va < 0.5).sum() > 30 and (va > 0.99).sum() > 300  # the shadow is there, and lit ground around it
    # measured: 0 for the cube, at most 8e-4 for the others; the mesh scaled by 1.03 gives 2e-3 to 9e-3
    assert np.mean(np.abs(va - vb)) < 1.5e-3, np.mean(np.abs(va - vb))
    assert np.mean(np.abs(va - vb) > 0.1) < 0.005


def test_axis_x_is_the_z_shape_turned(device):
    """axis = X maps the spine onto x: the same points as an axis-Z cylinder turned by 90 degrees about y."""
    a, b = _stage(), _stage()
    _define(a, "Cylinder", "/World/C", {"radius": 0.3, "height": 1.2}, axis="X")
    c = _define(b, "Cylinder", "/World/C", {"radius": 0.3, "height": 1.2})
    UsdGeom.XformCommonAPI(c).SetRotate(Gf.Vec3f(0, 90, 0))
    sa, fa = _v(a, device)
    sb, fb = _v(b, device)
    pa, pb = (np.unique(np.round(s.points[4:], 5), axis=0) for s in (sa, sb))  # the cylinder's (the ground's 4 first)
    assert len(pa) == SEGMENTS_FLAT * 2 + 2 and np.allclose(pa, pb, atol=1e-5)
    assert np.ptp(pa[:, 0]) == pytest.approx(1.2) and np.ptp(pa[:, 1]) == pytest.approx(0.6)  # the spine along x
    assert (fa["V"] < 0.5).sum() > 30 and np.mean(np.abs(fa["V"] - fb["V"])) < 1e-3


# --------------------------------------------------------------------------- geometry


EXTENT_CASES = [("Cube", {"size": 1.5}), ("Sphere", {"radius": 0.7}), ("Cylinder", {"radius": 0.4, "height": 2.5}),
                ("Cone", {"radius": 0.6, "height": 1.5}), ("Capsule", {"radius": 0.25, "height": 1.0}),
                ("Cylinder_1", {"radiusTop": 0.2, "radiusBottom": 0.7, "height": 1.2}),
                ("Capsule_1", {"radiusTop": 0.2, "radiusBottom": 0.7, "height": 1.0}),
                ("Capsule_1", {"radiusTop": 0.6, "radiusBottom": 0.1, "height": 0.5}),
                ("Plane", {"width": 2.0, "length": 4.0})]


@pytest.mark.parametrize("axis", ["X", "Y", "Z"])
def test_points_span_usds_own_extent(axis):
    """The tessellation's bounding box is the extent USD computes for the shape (its own
    ComputeExtent plugins), for every axis; an authored extent that disagrees changes nothing."""
    st = make_stage()
    cases = [(k, a) for k, a in EXTENT_CASES if hasattr(UsdGeom, k)]
    for i, (kind, attrs) in enumerate(cases):
        s = _define(st, kind, f"/World/S{i}", attrs, at=(0, 0, 0), axis=None if kind in ("Cube", "Sphere") else axis)
        s.CreateExtentAttr([(-9, -9, -9), (9, 9, 9)])  # wrong on purpose: size and radius define the shape
    scene = wsoft.load_scene(st)
    assert scene.prims == [f"/World/S{i}" for i in range(len(cases))]
    for i, (kind, attrs) in enumerate(cases):
        first, count = scene.prim_points[i]
        p = scene.points[first:first + count]
        ext = np.array(UsdGeom.Boundable.ComputeExtentFromPlugins(UsdGeom.Boundable(st.GetPrimAtPath(f"/World/S{i}")),
                                                                 Usd.TimeCode.Default()))
        assert np.allclose(p.min(axis=0), ext[0], atol=1e-5) and np.allclose(p.max(axis=0), ext[1], atol=1e-5), (kind, attrs, axis)


def _plane_gap(points, tris, centre, radius):
    """Per triangle, how far inside the sphere its plane is (radius - distance from the centre), over the radius."""
    q = points[tris].astype(np.float64) - centre
    n = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    return (radius - np.abs(np.einsum("ij,ij->i", n, q[:, 0]))) / radius


def test_silhouette_error_bound():
    """Every point of a tessellated sphere, capsule cap and cylinder side lies within SHAPE_TOLERANCE
    of the radius inside the true surface (and not much closer: the counts are not wasted)."""
    st = make_stage()
    _define(st, "Sphere", "/World/S", {"radius": 0.7}, at=(0, 0, 0))
    _define(st, "Cylinder", "/World/C", {"radius": 0.4, "height": 1.0}, at=(0, 0, 0))
    _define(st, "Capsule", "/World/K", {"radius": 0.3, "height": 1.0}, at=(0, 0, 0))
    scene = wsoft.load_scene(st)
    tris = {name: scene.triangles[scene.tri_prim == j] for j, name in enumerate(scene.prims)}
    assert len(tris["/World/S"]) == 2 * SEGMENTS_CURVED * (SEGMENTS_CURVED // 2 - 1) == 5040
    assert len(tris["/World/C"]) == 4 * SEGMENTS_FLAT == 208 and len(tris["/World/K"]) == 2 * SEGMENTS_CURVED * (SEGMENTS_CURVED // 2) == 5184
    p = scene.points.astype(np.float64)
    gap = _plane_gap(p, tris["/World/S"], 0.0, 0.7)
    assert np.all(np.abs(np.linalg.norm(p[np.unique(tris["/World/S"])], axis=1) - 0.7) < 1e-6)  # points on the sphere
    assert gap.max() <= SHAPE_TOLERANCE and gap.max() > 0.5 * SHAPE_TOLERANCE, gap.max()
    # the cylinder's side: its sagitta r (1 - cos(pi / n))
    side = tris["/World/C"][np.ptp(p[tris["/World/C"]][:, :, 2], axis=1) > 0]
    q = p[side]
    n = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    n[:, 2] = 0
    n /= np.linalg.norm(n, axis=1)[:, None]
    sag = (0.4 - np.einsum("ij,ij->i", n, q[:, 0])) / 0.4
    assert sag.max() <= SHAPE_TOLERANCE and sag.min() > 0.5 * SHAPE_TOLERANCE
    # the capsule's caps: hemispheres about z = +-0.5
    k = tris["/World/K"]
    for zc in (-0.5, 0.5):
        cap = k[np.all((p[k][:, :, 2] - zc) * np.sign(zc) >= -1e-6, axis=1)]
        assert len(cap) > 2000 and _plane_gap(p, cap, np.array([0, 0, zc]), 0.3).max() <= SHAPE_TOLERANCE


def test_capsule_1_is_the_hull_of_its_tangent_spheres():
    """Every point of a Capsule_1 lies on its bottom sphere, its top sphere or the frustum between
    the rings radiusBottom at -h/2 and radiusTop at +h/2, and those rings lie on the spheres."""
    if not hasattr(UsdGeom, "Capsule_1"):
        pytest.skip("this usd-core has no Capsule_1")
    rb, rt, h = 0.7, 0.2, 1.0
    st = make_stage()
    _define(st, "Capsule_1", "/World/K", {"radiusBottom": rb, "radiusTop": rt, "height": h}, at=(0, 0, 0))
    p = wsoft.load_scene(st).points.astype(np.float64)
    (RB, cb), (RT, ct) = _capsule_1_spheres(rb, rt, h)
    rad = np.linalg.norm(p[:, :2], axis=1)
    on_bottom = np.abs(np.linalg.norm(p - [0, 0, cb], axis=1) - RB) < 1e-6
    on_top = np.abs(np.linalg.norm(p - [0, 0, ct], axis=1) - RT) < 1e-6
    on_side = (np.abs(p[:, 2]) <= h / 2 + 1e-6) & (np.abs(rad - (rb + (rt - rb) * (p[:, 2] + h / 2) / h)) < 1e-6)
    assert np.all(on_bottom | on_top | on_side)
    assert np.any(on_side & on_bottom & (np.abs(p[:, 2] + h / 2) < 1e-6)) and np.any(on_side & on_top & (np.abs(p[:, 2] - h / 2) < 1e-6))


# --------------------------------------------------------------------------- the mesh path: instancing, sides, time, materials


def test_point_instancer_with_a_sphere_prototype(device):
    """A PointInstancer placing a Sphere: flattened, one tessellated sphere per instance; kept
    instanced, one prototype; both cast the shadow three Spheres placed by hand cast."""
    at = [(-1.0, 0.0, 1.0), (0.8, 0.3, 1.2), (0.0, -0.9, 0.8)]
    a = _stage()
    pi = UsdGeom.PointInstancer.Define(a, "/World/Balls")
    _define(a, "Sphere", "/World/Balls/Protos/Ball", {"radius": 0.3}, at=(0, 0, 0))
    pi.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Balls/Protos/Ball")])
    pi.CreateProtoIndicesAttr([0, 0, 0])
    pi.CreatePositionsAttr([Gf.Vec3f(*p) for p in at])
    b = _stage()
    for i, p in enumerate(at):
        _define(b, "Sphere", f"/World/Ball{i}", {"radius": 0.3}, at=p)
    sa, fa = _v(a, device)
    sb, fb = _v(b, device)
    assert sa.prims[1:] == [f"/World/Balls/Protos/Ball@/World/Balls[{i}]" for i in range(3)]
    assert len(sa.triangles) == len(sb.triangles) == 2 + 3 * 5040
    assert (fa["V"] < 0.5).sum() > 30 and np.mean(np.abs(fa["V"] - fb["V"])) < 1e-3
    si = wsoft.load_scene(a, instancing=True)
    assert len(si.instances.prototypes) == 1 and len(si.instances.prototypes[0].triangles) == 5040 and len(si.instances.proto) == 3
    fi = wsoft.render(si, "reference", width=W, height=H, device=device, samples=SAMPLES, seed=SEED)
    assert np.mean(np.abs(fi["V"] - fa["V"])) < 1e-3


def test_instanceable_prim_holding_a_shape():
    st = _stage()
    root = st.CreateClassPrim("/Protos")
    _define(st, "Cube", "/Protos/Rock/Body", {"size": 0.5}, at=(0, 0, 0))
    root.SetTypeName("Scope")
    for i in range(2):
        add_instance(st, f"/World/Rock{i}", "/Protos/Rock", (i - 0.5, 0, 1))
    flat = wsoft.load_scene(st)
    assert len(flat.triangles) == 2 + 2 * 12 and not any("ignored" in w for w in flat.warnings)
    kept = wsoft.load_scene(st, instancing=True)
    assert len(kept.instances.prototypes) == 1 and len(kept.instances.prototypes[0].triangles) == 12 and len(kept.instances.proto) == 2


def test_plane_is_double_sided_unless_told(device):
    """A Plane falls back to doubleSided = true (the schema's fallback): seen from below it covers
    the frame; with doubleSided = false its back face is culled there. Under the light it receives
    the shadow a quad of the same size does, facing +axis."""
    def stage(double_sided, below=False, quad=False):
        st = make_stage()
        if quad:
            add_quad(st, "/World/Ground", (0, 0, 0), 3, double_sided=True)
        else:
            g = _define(st, "Plane", "/World/Ground", {"width": 6.0, "length": 6.0}, at=(0, 0, 0))
            if double_sided is not None:
                g.CreateDoubleSidedAttr(double_sided)
        add_box(st, "/World/Box", (-0.4, -0.4, 0.8), (0.4, 0.4, 1.2))
        add_rect_light(st, "/World/Light", (2.0, 0, 3.0), 1, 1)
        add_camera(st, "/World/Cam", (-1.0, 0.01, -8) if below else (-1.5, -5, 6), (-1.0, 0, 0), focal=20)
        return st

    s, f = _v(stage(None), device)
    ground = s.tri_prim == 0
    assert s.tri_double_sided[ground].all() and len(s.triangles[ground]) == 2
    tri = s.points[s.triangles[ground]].astype(np.float64)
    assert np.all(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2] > 0)  # facing +Z
    _, fq = _v(stage(None, quad=True), device)
    assert (f["V"] < 0.5).sum() > 30 and np.array_equal(f["A"] > 0, fq["A"] > 0) and np.mean(np.abs(f["V"] - fq["V"])) < 1e-3
    _, up = _v(stage(None, below=True), device)
    s1, culled = _v(stage(False, below=True), device)
    assert not s1.tri_double_sided[s1.tri_prim == 0].any()
    assert (up["A"] > 0).mean() > 0.5 and (culled["A"] > 0).mean() < 0.05  # only the box is left


def test_orientation_time_samples_and_materials():
    st = make_stage()
    s = _define(st, "Sphere", "/World/Left", {"radius": 0.5}, at=(0, 0, 0))
    s.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    m = _define(st, "Cube", "/World/Mirrored", {"size": 1.0}, at=(3, 0, 0))
    UsdGeom.XformCommonAPI(m).SetScale(Gf.Vec3f(-1, 1, 1))
    r = _define(st, "Sphere", "/World/Grows", {}, at=(6, 0, 0))
    r.CreateRadiusAttr().Set(0.5, 1.0)
    r.GetRadiusAttr().Set(1.0, 10.0)
    set_display_color(r, (0.2, 0.4, 0.6))
    c = _define(st, "Cylinder", "/World/Painted", {}, at=(9, 0, 0))
    bind(c.GetPrim(), add_material(st, "/World/Looks/Red", (0.8, 0.1, 0.1)))
    pv = UsdGeom.PrimvarsAPI(c).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    pv.Set([(0, 0), (1, 0), (1, 1)])
    _define(st, "Cone", "/World/Guide", {}, at=(12, 0, 0)).CreatePurposeAttr(UsdGeom.Tokens.guide)
    _define(st, "Cone", "/World/Hidden", {}, at=(15, 0, 0)).MakeInvisible()
    st.SetStartTimeCode(1)
    st.SetEndTimeCode(10)
    s1, s10 = wsoft.load_scene(st, time=1.0), wsoft.load_scene(st, time=10.0)
    assert s1.prims == ["/World/Left", "/World/Mirrored", "/World/Grows", "/World/Painted"]
    closed = {n: set(s1.tri_closed[s1.tri_prim == j].tolist()) for j, n in enumerate(s1.prims)}
    assert closed == {"/World/Left": {-1}, "/World/Mirrored": {1}, "/World/Grows": {1}, "/World/Painted": {1}}
    dyn = {n: bool(s1.tri_dynamic[s1.tri_prim == j].any()) for j, n in enumerate(s1.prims)}
    assert dyn == {"/World/Left": False, "/World/Mirrored": False, "/World/Grows": True, "/World/Painted": False}
    for sc, radius in ((s1, 0.5), (s10, 1.0)):
        first, count = sc.prim_points[2]
        assert np.ptp(sc.points[first:first + count, 0]) == pytest.approx(2 * radius)
    mats = {sc_name: s1.materials[s1.tri_material[s1.tri_prim == j][0]] for j, sc_name in enumerate(s1.prims)}
    assert mats["/World/Grows"].albedo == pytest.approx((0.2, 0.4, 0.6)) and mats["/World/Painted"].path == "/World/Looks/Red"
    st_warn = [w for w in s1.warnings if "primvars:st" in w]
    assert len(st_warn) == 1 and "/World/Painted" in st_warn[0] and "faceVarying" in st_warn[0]


# --------------------------------------------------------------------------- what is not drawn, bad input


def test_other_gprims_keep_their_warning_and_shapes_lose_it():
    st = _stage()
    _define(st, "Sphere", "/World/Ball", {"radius": 0.3})
    for kind in ("NurbsPatch", "BasisCurves", "Points", "HermiteCurves"):
        if hasattr(UsdGeom, kind):
            getattr(UsdGeom, kind).Define(st, f"/World/{kind}")
    _define(st, "Sphere", "/World/Dot", {"radius": 0.0}, at=(2, 0, 1))
    scene = wsoft.load_scene(st)
    ignored = [w for w in scene.warnings if "ignored" in w]
    assert len(ignored) == 3 + hasattr(UsdGeom, "HermiteCurves") and all(" is not a Mesh or one of UsdGeom's shapes" in w for w in ignored)
    assert not any("/World/Ball" in w for w in scene.warnings)
    assert scene.prims == ["/World/Ground", "/World/Ball"]
    assert any("/World/Dot: Sphere has no area (radius = 0.0); nothing drawn" in w for w in scene.warnings)


def test_plan_of_a_stage_with_a_sphere_says_nothing_is_ignored(tmp_path):
    st = _stage()
    _define(st, "Sphere", "/World/Ball", {"radius": 0.3})
    st.GetRootLayer().Export(str(tmp_path / "ball.usda"))
    UsdGeom.BasisCurves.Define(st, "/World/Hair")
    st.GetRootLayer().Export(str(tmp_path / "hair.usda"))
    ball = wsoft_cli("plan", str(tmp_path / "ball.usda"))
    hair = wsoft_cli("plan", str(tmp_path / "hair.usda"))
    assert ball.returncode == 0 and hair.returncode == 0, ball.stderr + hair.stderr
    assert "ignored" not in ball.stdout + ball.stderr
    assert "/World/Hair: BasisCurves is not a Mesh" in hair.stdout + hair.stderr


@pytest.mark.parametrize("kind,attr,value,needle", [
    ("Sphere", "radius", -1.0, "radius = -1 is negative"),
    ("Cube", "size", -2.0, "size = -2 is negative"),
    ("Cylinder", "height", -0.5, "height = -0.5 is negative"),
    ("Plane", "width", -1.0, "width = -1 is negative"),
    ("Capsule_1", "radiusTop", -0.1, "radiusTop = -0.1 is negative"),
    ("Cone", "axis", "W", "axis = 'W' is not X, Y or Z"),
])
def test_bad_shape_is_one_line_naming_file_and_prim(tmp_path, kind, attr, value, needle):
    if not hasattr(UsdGeom, kind):
        pytest.skip(f"this usd-core has no {kind}")
    st = _stage()
    s = getattr(UsdGeom, kind).Define(st, "/World/Bad")
    getattr(s, f"Get{attr[0].upper()}{attr[1:]}Attr")().Set(value)
    path = str(tmp_path / "bad.usda")
    st.GetRootLayer().Export(path)
    with pytest.raises(SceneError, match=needle):
        wsoft.load_scene(path)
    p = wsoft_cli("plan", path)
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("wsoft: error")]
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert len(lines) == 1 and path in lines[0] and "/World/Bad" in lines[0] and needle in lines[0], p.stderr


def test_bake_leaves_shapes_out():
    """A shape has no authored points or faces to carry baked primvars: skipped with a warning, the
    meshes around it baked."""
    st = _stage()
    _define(st, "Sphere", "/World/Ball", {"radius": 0.4})
    stats: dict = {}
    wsoft.bake(st, "hard", device="cpu", stats=stats)
    assert "/World/Ground" in stats["meshes"] and "/World/Ball" not in stats["meshes"]
    assert "Sphere" in stats["skipped_meshes"]["/World/Ball"]
    assert any("/World/Ball: a Sphere has no authored points or faces" in w for w in stats["warnings"])
