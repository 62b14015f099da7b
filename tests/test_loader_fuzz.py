"""The mesh and stage loader on inputs a fuzz pass finds: ``holeIndices``, concave and
self-crossing faces (against the fan every convex face keeps), open stages with load rules and
population masks loaded again, and time samples on a stage that authors no time range."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import add_camera, add_quad, add_rect_light, make_stage
from hypothesis import given, settings
from hypothesis import strategies as st

import wsoft
from wsoft.stages import add_mesh


def _mesh(stage, path, points, counts, indices, **kw):
    return add_mesh(stage, path, (np.asarray(points, np.float64), counts, indices), minimal=True, **kw)


def _signed_areas(scene, axis=2):
    """Each triangle's signed area along ``axis`` (counter-clockwise seen from +axis: positive)."""
    p = scene.points[scene.triangles].astype(np.float64)
    return 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, axis]


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _shoelace(xy) -> float:
    x, y = np.asarray(xy, np.float64).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _warnings_with(scene, text):
    return [w for w in scene.warnings if text in w]


# -- holeIndices ------------------------------------------------------------------------------------


def test_hole_faces_are_not_drawn_and_the_rest_keep_their_faces_and_st():
    """Faces listed in holeIndices cast nothing; the other faces keep their face index (GeomSubset
    materials, uniform primvars) and their corners' st."""
    s = make_stage()
    pts = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)]
    m = _mesh(s, "/World/Strip", pts, [4, 4], [0, 1, 4, 3, 1, 2, 5, 4], st=[(p[0], p[1]) for p in pts], st_interpolation="vertex")
    m.CreateHoleIndicesAttr([0])
    lone = add_quad(s, "/World/Lone", (0, 0, 2), 0.5)
    lone.CreateHoleIndicesAttr([0])
    add_rect_light(s, "/World/L", (0, 0, 5), 1, 1)
    scene = wsoft.load_scene(s)
    strip = scene.tri_prim == scene.prims.index("/World/Strip")
    assert strip.sum() == 2 and scene.triangle_count == 2  # the lone quad's only face is a hole
    assert (scene.tri_face[strip] == 1).all()
    corners = scene.points[scene.triangles[strip]]
    assert corners[..., 0].min() == 1.0  # face 1 spans x in [1, 2]
    np.testing.assert_array_equal(scene.tri_uv[strip], corners[..., :2])
    assert not scene.warnings


def test_out_of_range_hole_indices_are_a_warning_naming_the_prim():
    s = make_stage()
    q = add_quad(s, "/World/Q", (0, 0, 0), 1)
    q.CreateHoleIndicesAttr([3, -1])
    add_rect_light(s, "/World/L", (0, 0, 5), 1, 1)
    scene = wsoft.load_scene(s)
    assert scene.triangle_count == 2  # the quad is drawn
    (w,) = _warnings_with(scene, "holeIndices")
    assert "/World/Q" in w and "2 of 2 indices out of range for 1 faces" in w


def test_a_hole_casts_no_shadow(device):
    """The base's occluder with its only face a hole: the reference and hard leave every pixel lit."""
    s = make_stage()
    add_quad(s, "/World/Ground", (0, 0, 0), 5)
    add_quad(s, "/World/Occluder", (0, 0, 1), 1).CreateHoleIndicesAttr([0])
    add_rect_light(s, "/World/Light", (0, 0, 3), 1, 1)
    add_camera(s, "/World/Cam", (0, -6, 5), (0, 0, 0))
    scene = wsoft.load_scene(s)
    for tech, kw in (("hard", {"shadow_map_size": 256}), ("reference", {"samples": 16})):
        f = wsoft.render(scene, tech, width=24, height=18, device=device, **kw)
        assert f.V[f["A"] > 0].min() == 1.0, tech


# -- concave, self-crossing and non-planar faces ----------------------------------------------------

# notched from above, the notch's corner (index 3) below the diagonal from corner 0: the fan from
# corner 0 is no triangulation of it
NOTCHED = [(-1, -1), (1, -1), (1, 1), (0, -0.6), (-1, 1)]


def _inside(xy, pts) -> np.ndarray:
    """Even-odd point-in-polygon of points ``pts`` [N, 2] in the outline ``xy``."""
    xy = np.asarray(xy, np.float64)
    a, b = xy, np.roll(xy, -1, axis=0)
    x, y = pts[:, 0:1], pts[:, 1:2]
    crosses = ((a[:, 1] > y) != (b[:, 1] > y)) & (x < a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1] + 1e-300))
    return crosses.sum(axis=1) % 2 == 1


def _tiles(tri_xy, xy, rng, n=4000):
    """Do the triangles ``tri_xy`` [T, 3, 2] tile the outline ``xy``? Each turns counter-clockwise,
    their areas sum to its area, and random points are held by one triangle inside it, by none
    outside (points within 1e-6 of its outline aside)."""
    t = np.asarray(tri_xy, np.float64)
    areas = 0.5 * _cross2(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    assert (areas > 0).all() and areas.sum() == pytest.approx(_shoelace(xy), rel=1e-5)
    pts = rng.uniform(np.min(xy, axis=0), np.max(xy, axis=0), size=(n, 2))
    hits = np.zeros(n, np.int64)
    for tri in t:
        hits += np.all([_cross2(tri[(k + 1) % 3] - tri[k], pts - tri[k]) > 0 for k in range(3)], axis=0)
    far = ~_near_edge(xy, pts)
    inside = _inside(xy, pts)
    assert (hits[far & inside] == 1).all() and (hits[far & ~inside] == 0).all()


def _near_edge(xy, pts, eps=1e-6):
    xy = np.asarray(xy, np.float64)
    a, ab = xy, np.roll(xy, -1, axis=0) - xy
    t = np.clip(((pts[:, None, :] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
    return (np.linalg.norm(pts[:, None, :] - (a + t[..., None] * ab), axis=-1) < eps).any(axis=1)


def _ngon_stage(xy, z=0.0, start=0, **kw):
    s = make_stage()
    n = len(xy)
    _mesh(s, "/World/F", [(x, y, z) for x, y in xy], [n], [(start + i) % n for i in range(n)], **kw)
    add_rect_light(s, "/World/L", (0, 0, 5), 1, 1)
    return s


def test_a_concave_pentagon_is_split_inside_its_outline():
    """The notched pentagon's triangles tile it (the fan from corner 0 covers part of the notch
    and winds one triangle backwards); the face index and per-corner st follow the new triangles."""
    xy = NOTCHED
    s = _ngon_stage(xy, st=[(x + 5, y + 7) for x, y in xy], st_interpolation="faceVarying")
    scene = wsoft.load_scene(s)
    assert scene.triangle_count == 3 and not scene.warnings
    _tiles(scene.points[scene.triangles][..., :2], xy, np.random.default_rng(1))
    assert (scene.tri_face == 0).all()
    np.testing.assert_allclose(scene.tri_uv, scene.points[scene.triangles][..., :2] + [5, 7])


def test_concave_faces_keep_orientation_and_mirroring():
    """leftHanded flips the new triangles as it flips a fan; a mirroring transform keeps their facing."""
    from pxr import Gf, UsdGeom

    for left, mirror in ((True, False), (False, True), (True, True)):
        s = _ngon_stage(NOTCHED)
        m = UsdGeom.Mesh(s.GetPrimAtPath("/World/F"))
        if left:
            m.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
        if mirror:
            UsdGeom.XformCommonAPI(m).SetScale(Gf.Vec3f(-1, 1, 1))
        scene = wsoft.load_scene(s)
        a = _signed_areas(scene)
        want = -1 if left else 1  # leftHanded: clockwise seen from +z is the front; a mirror keeps the facing
        assert (np.sign(a) == want).all() and abs(a.sum()) == pytest.approx(abs(_shoelace(NOTCHED)), rel=1e-5)


def test_convex_faces_keep_the_fan_from_their_first_corner():
    """Triangles, quads and convex n-gons (any first corner, any plane) keep (c0, ci, ci+1) in order."""
    rng = np.random.default_rng(3)
    s = make_stage()
    counts, idx, pts = [], [], []
    for n in [3, 4, 4, 5, 6, 7, 8, 12, 32]:
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        r = rng.uniform(0.5, 2.0)
        rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        ring = np.c_[r * np.cos(ang), r * np.sin(ang), np.zeros(n)] @ rot.T + rng.uniform(-5, 5, 3)
        start = int(rng.integers(n))
        counts.append(n)
        idx += [len(pts) + (start + i) % n for i in range(n)]
        pts += ring.tolist()
    _mesh(s, "/World/Convex", pts, counts, idx)
    add_rect_light(s, "/World/L", (0, 0, 9), 1, 1)
    scene = wsoft.load_scene(s)
    want, face = [], []
    c = 0
    for f, n in enumerate(counts):
        want += [[idx[c], idx[c + k], idx[c + k + 1]] for k in range(1, n - 1)]
        face += [f] * (n - 2)
        c += n
    np.testing.assert_array_equal(scene.triangles, want)
    np.testing.assert_array_equal(scene.tri_face, face)
    assert not scene.warnings


@settings(max_examples=60, deadline=None)
@given(radii=st.lists(st.floats(0.2, 2.0), min_size=4, max_size=12), jitter=st.lists(st.floats(-0.4, 0.4), min_size=12, max_size=12),
       start=st.integers(0, 11), tilt=st.floats(-80, 80))
def test_random_star_shaped_faces_are_tiled(radii, jitter, start, tilt):
    """Simple faces (star-shaped about the origin, corners at random radii), begun at any corner and
    tilted out of the XY plane: seen along the face's normal, their triangles tile the outline."""
    from pxr import Gf, UsdGeom

    n = len(radii)
    ang = 2 * np.pi * (np.arange(n) + 0.5 * np.asarray(jitter[:n])) / n
    xy = np.c_[np.asarray(radii) * np.cos(ang), np.asarray(radii) * np.sin(ang)]
    s = _ngon_stage(xy, start=start % n)
    UsdGeom.XformCommonAPI(s.GetPrimAtPath("/World/F")).SetRotate(Gf.Vec3f(float(tilt), 0, 0))
    scene = wsoft.load_scene(s)
    assert not scene.warnings
    c, si = np.cos(np.radians(tilt)), np.sin(np.radians(tilt))
    p = scene.points[scene.triangles].astype(np.float64)
    back = np.stack([p[..., 0], c * p[..., 1] + si * p[..., 2]], axis=-1)  # the rotation about x undone, in the face's plane
    _tiles(back, xy, np.random.default_rng(start), n=1000)


def test_self_crossing_and_non_planar_faces_are_warned_once_per_mesh():
    """Two bow ties and a pentagram: one warning counting 3 faces (triangulated as fans); two
    notched pentagons bent out of their plane: one warning counting 2 (triangulated on their
    best-fit plane). The faces are still drawn."""
    s = make_stage()
    bow = [(0, 0, 0), (1, 1, 0), (1, 0, 0), (0, 1, 0)]
    a = np.pi / 2 + 2 * np.pi * np.arange(5) / 5
    star = np.c_[np.cos(a), np.sin(a), np.zeros(5)][[0, 2, 4, 1, 3]] + [3, 0, 0]
    _mesh(s, "/World/Crossed", bow + [(x + 1.5, y, z) for x, y, z in bow] + star.tolist(), [4, 4, 5],
          list(range(13)))
    bent = [(x, y, 0.3 * x * x) for x, y in NOTCHED]
    _mesh(s, "/World/Bent", bent + [(x + 3, y, z) for x, y, z in bent], [5, 5], list(range(10)))
    add_rect_light(s, "/World/L", (0, 0, 5), 1, 1)
    scene = wsoft.load_scene(s)
    (crossed,) = _warnings_with(scene, "cross themselves")
    assert "/World/Crossed" in crossed and "3 faces" in crossed
    (bent_w,) = _warnings_with(scene, "not planar")
    assert "/World/Bent" in bent_w and "2 concave faces" in bent_w
    assert len(scene.warnings) == 2
    bent_tris = scene.tri_prim == scene.prims.index("/World/Bent")
    assert bent_tris.sum() == 6 and (scene.tri_prim == scene.prims.index("/World/Crossed")).sum() == 7


def test_a_large_mesh_of_quads_keeps_the_fan_quickly():
    """A 300 x 300 grid of quads and one concave quad (a dart whose first corner does not see all
    of it): only the dart is split anew, every other quad keeps its fan."""
    import time

    from wsoft.scene.polygons import fan, triangulate

    n = 300
    x, y = np.meshgrid(np.arange(n + 1, dtype=np.float64), np.arange(n + 1, dtype=np.float64))
    pts = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    v0 = (j * (n + 1) + i).ravel()
    quads = np.stack([v0, v0 + 1, v0 + n + 2, v0 + n + 1], 1)
    dart = [(2, 1, 5), (0.8, 0.8, 5), (1, 2, 5), (0, 0, 5)]  # reflex at its second corner
    quads[n * n // 2] = len(pts) + np.arange(4)
    pts = np.vstack([pts, dart])
    t0 = time.perf_counter()
    tri = triangulate(pts, np.full(n * n, 4), quads.ravel())
    took = time.perf_counter() - t0
    corners, faces = fan(np.full(n * n, 4))
    split = faces == n * n // 2
    assert tri.ear_clipped == 1 and (tri.faces == faces).all()
    assert (tri.corners[~split] == corners[~split]).all() and not (tri.corners[split] == corners[split]).all()
    assert took < 2.0


# -- an open stage loaded again ---------------------------------------------------------------------


def _payload_stage(tmp_path):
    """A ground, occluder, light and camera, two render settings, and a payload holding a
    2-quad mesh (4 triangles)."""
    from pxr import Gf, UsdRender

    prop = make_stage()
    add_mesh(prop, "/Prop", (np.array([(2, 2, 1), (3, 2, 1), (4, 2, 1), (2, 3, 1), (3, 3, 1), (4, 3, 1)], np.float64),
                            [4, 4], [0, 1, 4, 3, 1, 2, 5, 4]), minimal=True)
    prop.SetDefaultPrim(prop.GetPrimAtPath("/Prop"))
    prop.GetRootLayer().Export(str(tmp_path / "prop.usda"))
    s = make_stage()
    add_quad(s, "/World/Ground", (0, 0, 0), 5)
    add_quad(s, "/World/Occluder", (0, 0, 1), 1)
    add_rect_light(s, "/World/Light", (0, 0, 3), 1, 1)
    add_camera(s, "/World/Cam", (0, -6, 5), (0, 0, 0))
    s.DefinePrim("/World/Prop").GetPayloads().AddPayload("./prop.usda")
    for path, res in (("/Render/A", (24, 18)), ("/Render/B", (18, 24))):
        UsdRender.Settings.Define(s, path).CreateResolutionAttr(Gf.Vec2i(*res))
    path = str(tmp_path / "root.usda")
    s.GetRootLayer().Export(path)
    return path


def test_an_open_stage_is_loaded_again_with_its_load_rules_and_mask(tmp_path):
    """A stage opened with LoadNone (its payload unloaded) and one with a population mask, loaded
    with render settings A and rendered with B: the render reads the same stage (4 triangles, the
    ground's and occluder's), not the file with its payload loaded."""
    from pxr import Usd

    from wsoft.pipeline import with_render_settings

    path = _payload_stage(tmp_path)
    assert wsoft.load_scene(path).total_triangles == 8  # the file opened afresh: the payload loaded
    unloaded = Usd.Stage.Open(path, Usd.Stage.LoadNone)
    masked = Usd.Stage.OpenMasked(path, Usd.StagePopulationMask(["/World/Ground", "/World/Light", "/World/Cam", "/Render"]))
    for stage, want in ((unloaded, 4), (masked, 2)):
        scene = wsoft.load_scene(stage, render_settings="/Render/A")
        assert scene.total_triangles == want
        again = with_render_settings(scene, "/Render/B")
        assert again.render_settings.path == "/Render/B" and again.total_triangles == want
        f = wsoft.render(scene, "hard", render_settings="/Render/B", device="cpu", shadow_map_size=256)
        assert f.stats["scene"]["triangles"] == want and f.V.shape == (24, 18)
    assert not unloaded.GetPrimAtPath("/World/Prop").IsLoaded()  # the caller's stage is left as it was


def test_bake_and_flattened_read_the_open_stage_a_scene_came_from(tmp_path):
    """wsoft.bake of a Scene of a LoadNone stage bakes the meshes that stage shows (no payload
    mesh); Scene.flattened of an instanced load reads that stage too."""
    from pxr import Usd

    path = _payload_stage(tmp_path)
    stage = Usd.Stage.Open(path, Usd.Stage.LoadNone)
    scene = wsoft.load_scene(stage)
    stats = {}
    wsoft.bake(scene, "hard", device="cpu", stats=stats, shadow_map_size=256)
    assert sorted(stats["meshes"]) == ["/World/Ground", "/World/Occluder"]
    assert wsoft.load_scene(stage, instancing=True).flattened().total_triangles == 4


# -- time samples without a time range --------------------------------------------------------------


def _animated_stage(time_range=False):
    """A ground; an occluder and a rect light whose translates are only time samples (at 12, the
    occluder at z = 1 and the light at z = 3; at 24, elsewhere); an optional time range 20..30."""
    from pxr import Gf, UsdGeom

    s = make_stage()
    add_quad(s, "/World/Ground", (0, 0, 0), 5)
    occ = add_quad(s, "/World/Occluder", (0, 0, 0), 1)
    op = UsdGeom.Xformable(occ).AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 1), 12.0)
    op.Set(Gf.Vec3d(1, 0, 2), 24.0)
    (op,) = UsdGeom.Xformable(add_rect_light(s, "/World/Light", (0, 0, 0), 1, 1)).GetOrderedXformOps()
    op.GetAttr().ClearDefault()
    op.Set(Gf.Vec3d(0, 0, 3), 12.0)
    op.Set(Gf.Vec3d(2, 0, 4), 24.0)
    if time_range:
        s.SetStartTimeCode(20)
        s.SetEndTimeCode(30)
    return s


def test_time_samples_without_a_time_range_load_at_the_earliest_sample():
    """No startTimeCode / endTimeCode and no time: the earliest time sample (12), with a warning
    naming it; Scene.time, the plan and a frame's stats say 12. A time range or a given time: as
    asked, no warning."""
    s = _animated_stage()
    scene = wsoft.load_scene(s)
    assert scene.time == 12.0
    np.testing.assert_allclose(scene.lights[0].position, (0, 0, 3))
    occ = scene.tri_prim == scene.prims.index("/World/Occluder")
    assert np.allclose(scene.points[scene.triangles[occ]][..., 2], 1.0)
    (w,) = _warnings_with(scene, "time code 12")
    assert "no time range" in w
    assert wsoft.plan(scene, ["hard"])["time"] == 12.0
    f = wsoft.render(scene, "hard", width=24, height=18, device="cpu", shadow_map_size=256)
    assert f.stats["scene"]["time"] == 12.0
    given = wsoft.load_scene(s, time=24)
    assert given.time == 24.0 and not _warnings_with(given, "time code")
    np.testing.assert_allclose(given.lights[0].position, (2, 0, 4))
    ranged = wsoft.load_scene(_animated_stage(time_range=True))
    assert ranged.time == 20.0 and not _warnings_with(ranged, "time code")


def test_the_earliest_sample_is_in_stage_time_through_a_layer_offset(tmp_path):
    """A sublayer authored with samples at 12 and 24, offset by +100 into the root: loaded at 112."""
    from pxr import Sdf, Usd

    sub = _animated_stage()
    sub.GetRootLayer().Export(str(tmp_path / "anim.usda"))
    root = Usd.Stage.CreateNew(str(tmp_path / "root.usda"))
    root.GetRootLayer().subLayerPaths.append("./anim.usda")
    root.GetRootLayer().subLayerOffsets[0] = Sdf.LayerOffset(100)
    root.GetRootLayer().Save()
    scene = wsoft.load_scene(str(tmp_path / "root.usda"))
    assert scene.time == 112.0 and _warnings_with(scene, "time code 112")
    np.testing.assert_allclose(scene.lights[0].position, (0, 0, 3))
