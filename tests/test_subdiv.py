"""Subdivision surfaces (:mod:`wsoft.scene.subdiv`) and their loading (``load_scene(subdiv_level=N)``,
``--subdiv-level``): known limit positions, B-spline reproduction on regular grids, boundaries,
creases and corners, primvars and GeomSubsets through refinement, and the errors."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from conftest import add_quad, add_rect_light, make_stage

import wsoft
from wsoft.errors import ParameterError, SceneError
from wsoft.scene.subdiv import (MAX_LEVEL, Tags, check_level, crease_edges, limit_points_catmull_clark, limit_points_loop, refine,
                                refined_face_count)
from wsoft.stages import add_mesh
from wsoft.stages.mesh import box_mesh


def _cube():
    return box_mesh((0, 0, 0), (1, 1, 1))


def _grid(nx: int, ny: int, z=None):
    """An open nx x ny grid of unit quads in the XY plane (points (i, j) at i + j (nx + 1))."""
    i, j = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="xy")
    p = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1).astype(np.float64)
    if z is not None:
        p[:, 2] = z
    fi, fj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    fi, fj = fi.ravel(), fj.ravel()
    v = lambda a, b: a + b * (nx + 1)  # noqa: E731
    quads = np.stack([v(fi, fj), v(fi + 1, fj), v(fi + 1, fj + 1), v(fi, fj + 1)], axis=1)
    return p, np.full(nx * ny, 4), quads.ravel()


def _torus(n: int, m: int, rng):
    """A closed n x m periodic quad grid (a torus's topology) with random points, and each point's (u, v)."""
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    uv = np.stack([i.ravel(), j.ravel()], axis=1).astype(np.float64)
    v = lambda a, b: (a % n) * m + (b % m)  # noqa: E731
    a, b = i.ravel(), j.ravel()
    quads = np.stack([v(a, b), v(a + 1, b), v(a + 1, b + 1), v(a, b + 1)], axis=1)
    return rng.normal(size=(n * m, 3)), np.full(n * m, 4), quads.ravel(), uv


def _bspline(t):
    """The centred uniform cubic B-spline."""
    t = np.abs(t)
    return np.where(t < 1, 2 / 3 - t * t + t ** 3 / 2, np.where(t < 2, (2 - t) ** 3 / 6, 0.0))


def _boundary_vertices(r) -> np.ndarray:
    """The vertices of a refinement's edges that have one face."""
    q = r.indices.reshape(-1, 4) if (r.counts == 4).all() else r.indices.reshape(-1, 3)
    e = np.concatenate([q[:, [k, (k + 1) % q.shape[1]]] for k in range(q.shape[1])])
    keys, cnt = np.unique(np.sort(e, axis=1), axis=0, return_counts=True)
    return np.unique(keys[cnt == 1])


def _curve(points, corner, level: int, closed: bool):
    """A polyline refined by the cubic B-spline rules (vertex (a + 6 v + b) / 8, edge midpoint),
    vertices flagged ``corner`` kept; open curves keep their ends."""
    p, c = np.asarray(points, np.float64), np.asarray(corner, bool)
    for _ in range(level):
        nxt = np.roll(p, -1, axis=0)
        vp = (np.roll(p, 1, axis=0) + 6 * p + nxt) / 8
        if not closed:
            c = c.copy()
            c[[0, -1]] = True
        vp = np.where(c[:, None], p, vp)
        mid = (p + nxt) / 2
        out = np.empty((2 * len(p), 3))
        out[0::2], out[1::2] = vp, mid
        cc = np.zeros(2 * len(p), bool)
        cc[0::2] = c
        p, c = (out, cc) if closed else (out[:-1], cc[:-1])
    return p


def _contains(points, wanted, tol=1e-12) -> bool:
    d = np.linalg.norm(points[None, :, :] - wanted[:, None, :], axis=2).min(axis=1)
    return bool(d.max() < tol)


# -- limit positions ---------------------------------------------------------------------------------


def test_cube_converges_to_the_catmull_clark_limit_of_its_corners():
    """Each corner of a unit cube (valence 3) has the limit (n^2 v + 4 sum e + sum f) / (n (n + 5)) =
    (1/4, 1/4, 1/4) from the corner at the origin; refined corners approach it (the error shrinks 6x a
    level from level 1 on: the eigenvalue 1/6 of a valence-3 vertex) and the limit mask applied at any level
    gives it again (the rules and the mask agree)."""
    p, counts, idx = _cube()
    limit = limit_points_catmull_clark(p, counts, idx)
    np.testing.assert_allclose(limit[0], [0.25, 0.25, 0.25])
    np.testing.assert_allclose(limit[7], [0.75, 0.75, 0.75])
    errors = []
    for level in range(MAX_LEVEL + 1):
        r = refine(p, counts, idx, "catmullClark", level)
        assert len(r.counts) == 6 * 4 ** level and (r.counts == 4).all()
        errors.append(np.abs(r.points[:8] - limit).max())
        np.testing.assert_allclose(limit_points_catmull_clark(r.points, r.counts, r.indices)[:8], limit, atol=1e-14)
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert errors[0] == 0.25 and errors[-1] < 2e-4
    np.testing.assert_allclose(ratios[1:], 6.0, rtol=1e-6)  # from level 1 on; the cage's first step gains 9x
    assert ratios[0] > 6


def test_periodic_quad_grid_reproduces_the_bicubic_b_spline():
    """A regular quad grid (a torus's topology, random points) refined once: the limit of every
    refined vertex (vertex, edge and face points) is the uniform bicubic B-spline of the cage at
    that vertex's parameter."""
    rng = np.random.default_rng(1)
    n, m = 6, 5
    p, counts, idx, uv = _torus(n, m, rng)
    r = refine(p, counts, idx, "catmullClark", 1)
    st = r.steps[0]

    def mid(a, b, period):  # the periodic midpoint of parameters a, b one unit apart
        d = (b - a + period / 2) % period - period / 2
        return a + d / 2

    per = np.array([n, m], np.float64)
    e_uv = mid(uv[st.ev[:, 0]], uv[st.ev[:, 1]], per)
    q = idx.reshape(-1, 4)
    f_uv = mid(uv[q[:, 0]], uv[q[:, 2]], per)
    params = np.concatenate([uv, e_uv, f_uv])
    k = np.arange(n)[:, None]
    l_ = np.arange(m)[None, :]

    def spline(u, v):
        du = (u - k + n / 2) % n - n / 2  # periodic distance to each control column
        dv = (v - l_ + m / 2) % m - m / 2
        w = _bspline(du) * _bspline(dv)  # [n, m]
        return w.ravel() @ p

    want = np.array([spline(u, v) for u, v in params])
    got = limit_points_catmull_clark(r.points, r.counts, r.indices)
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_loop_converges_to_the_box_spline_limit():
    """Loop's limit mask (1 - n chi) v + chi sum(neighbours), chi = 1 / (3 / (8 beta) + n): at
    valence 6 (a regular triangulated torus) the quartic box spline's 1/2 and 1/12; at valence 4 (an
    octahedron) beta = 31/256. Refined vertices approach it; the mask at any level gives it again."""
    rng = np.random.default_rng(2)
    n, m = 6, 6
    p, _, idx, _ = _torus(n, m, rng)
    q = idx.reshape(-1, 4)
    tris = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]], axis=1).ravel()
    limit = limit_points_loop(p, tris)
    nb = np.unique(np.sort(np.concatenate([tris.reshape(-1, 3)[:, [a, b]] for a, b in ((0, 1), (1, 2), (2, 0))]), axis=1), axis=0)
    assert (np.bincount(nb.ravel()) == 6).all()  # regular
    s = np.zeros_like(p)
    np.add.at(s, nb[:, 0], p[nb[:, 1]])
    np.add.at(s, nb[:, 1], p[nb[:, 0]])
    np.testing.assert_allclose(limit, p / 2 + s / 12, atol=1e-14)
    octa = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)
    otris = [0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5]
    beta = 31 / 256
    chi = 1 / (3 / (8 * beta) + 4)
    olimit = limit_points_loop(octa, otris)
    np.testing.assert_allclose(olimit[0], [(1 - 4 * chi), 0, 0], atol=1e-14)
    for pts, t, lim in ((p, tris, limit), (octa, otris, olimit)):
        errors = []
        for level in range(MAX_LEVEL + 1):
            r = refine(pts, np.full(len(t) // 3, 3), t, "loop", level)
            assert len(r.counts) == len(t) // 3 * 4 ** level
            errors.append(np.abs(r.points[:len(pts)] - lim).max())
            np.testing.assert_allclose(limit_points_loop(r.points, r.indices)[:len(pts)], lim, atol=1e-13)
        ratios = np.array(errors[:-1]) / np.array(errors[1:])
        assert ratios.min() > 3.99 and errors[-1] < 5e-3 * errors[0], ratios  # 4x a level at valence 6, 7.1x at valence 4


def test_flat_meshes_stay_flat_and_affine_data_stays_affine():
    """Every scheme reproduces planes: a jittered grid of quads, a triangle and a pentagon in z = 0
    stays in it; points on a tilted plane stay on it (the rules are affine combinations)."""
    rng = np.random.default_rng(3)
    p, counts, idx = _grid(4, 3)
    p[:, :2] += rng.uniform(-0.2, 0.2, size=(len(p), 2))
    extra = np.array([[5, 0, 0], [6, 0.5, 0], [6.5, 1.5, 0], [5.5, 2.5, 0], [4.8, 1.5, 0]])
    p2 = np.concatenate([p, extra])
    v0 = len(p)
    counts2 = np.concatenate([counts, [3, 5]])
    idx2 = np.concatenate([idx, [4, v0, v0 + 4], v0 + np.arange(5)])
    for scheme, (pts, c, i) in (("catmullClark", (p2, counts2, idx2)), ("bilinear", (p2, counts2, idx2)),
                                ("loop", (p, np.full(2 * len(counts), 3), np.concatenate([idx.reshape(-1, 4)[:, [0, 1, 2]],
                                                                                           idx.reshape(-1, 4)[:, [0, 2, 3]]], 1).ravel()))):
        r = refine(pts, c, i, scheme, 3)
        assert np.abs(r.points[:, 2]).max() == 0.0, scheme
        tilted = pts.copy()
        tilted[:, 2] = 0.3 * pts[:, 0] - 0.7 * pts[:, 1] + 2.0
        rt = refine(tilted, c, i, scheme, 3)
        np.testing.assert_allclose(rt.points[:, 2], 0.3 * rt.points[:, 0] - 0.7 * rt.points[:, 1] + 2.0, atol=1e-12)


# -- boundaries, creases, corners ---------------------------------------------------------------------


@pytest.mark.parametrize("boundary", ["edgeAndCorner", "edgeOnly"])
def test_boundary_is_the_cubic_b_spline_of_the_boundary_vertices(boundary):
    """An open grid's refined boundary is the cubic B-spline subdivision of its boundary polygon
    alone (moving interior points moves none of it); edgeAndCorner keeps the grid's corners."""
    rng = np.random.default_rng(4)
    nx, ny = 4, 3
    p, counts, idx = _grid(nx, ny, z=rng.normal(size=(nx + 1) * (ny + 1)))
    loop = [i for i in range(nx + 1)] + [nx + j * (nx + 1) for j in range(1, ny + 1)]
    loop += [ny * (nx + 1) + i for i in range(nx - 1, -1, -1)] + [j * (nx + 1) for j in range(ny - 1, 0, -1)]
    corners = np.isin(loop, [0, nx, ny * (nx + 1), ny * (nx + 1) + nx]) & (boundary == "edgeAndCorner")
    level = 3
    r = refine(p, counts, idx, "catmullClark", level, Tags(boundary=boundary))
    bv = _boundary_vertices(r)
    want = _curve(p[loop], corners, level, closed=True)
    assert len(bv) == len(want) and _contains(r.points[bv], want)
    moved = p.copy()
    interior = np.setdiff1d(np.arange(len(p)), loop)
    moved[interior] += rng.normal(size=(len(interior), 3))
    r2 = refine(moved, counts, idx, "catmullClark", level, Tags(boundary=boundary))
    np.testing.assert_array_equal(r2.points[bv], r.points[bv])
    assert not np.allclose(r2.points, r.points)
    corner0 = np.abs(r.points[0] - p[0]).max()
    assert (corner0 == 0.0) == (boundary == "edgeAndCorner")


def test_an_infinitely_sharp_crease_is_a_b_spline_curve_and_a_corner_stays_put():
    """An interior row of edges with sharpness 10 (infinite): the refined crease is the cubic
    B-spline of the crease vertices (its ends, where it meets the boundary, fixed), whatever the
    points beside it; an interior vertex with cornerSharpness 10 does not move, one with 0 does."""
    rng = np.random.default_rng(5)
    nx, ny = 5, 4
    p, counts, idx = _grid(nx, ny, z=rng.normal(size=(nx + 1) * (ny + 1)))
    row = [2 * (nx + 1) + i for i in range(nx + 1)]
    edges, sharp = crease_edges(row, [len(row)], [10.0])
    assert edges.shape == (nx, 2) and (sharp == 10.0).all()
    corner = 1 * (nx + 1) + 2
    tags = Tags(crease_edges=edges, crease_sharpness=sharp, corners=np.array([corner]), corner_sharpness=np.array([10.0]))
    level = 3
    r = refine(p, counts, idx, "catmullClark", level, tags)
    want = _curve(p[row], np.zeros(len(row), bool), level, closed=False)
    assert _contains(r.points, want)
    np.testing.assert_array_equal(r.points[corner], p[corner])
    smooth = refine(p, counts, idx, "catmullClark", level)
    assert not _contains(smooth.points, want[1:-1], tol=1e-6) and np.abs(smooth.points[corner] - p[corner]).max() > 1e-3
    off = np.setdiff1d(np.arange(len(p)), row + [corner])
    moved = p.copy()
    moved[off] += 1.0
    assert _contains(refine(moved, counts, idx, "catmullClark", level, tags).points, want)


def test_semi_sharp_creases_blend_and_decay():
    """Sharpness 1 acts as infinite for one level and is smooth after; sharpness 0.5 gives, at level
    1, exactly the mean of the smooth (0) and the sharp (1) results (OpenSubdiv's semi-sharp rule)."""
    rng = np.random.default_rng(6)
    p, counts, idx = _grid(4, 4, z=rng.normal(size=25))
    row = [2 * 5 + i for i in range(5)]

    def run(s, level):
        e, sh = crease_edges(row, [5], [s])
        return refine(p, counts, idx, "catmullClark", level, Tags(crease_edges=e, crease_sharpness=sh)).points

    np.testing.assert_allclose(run(0.5, 1), (run(0.0, 1) + run(1.0, 1)) / 2, atol=1e-14)
    np.testing.assert_array_equal(run(1.0, 1), run(10.0, 1))
    assert not np.allclose(run(1.0, 2), run(10.0, 2)) and not np.allclose(run(1.0, 2), run(0.0, 2))
    np.testing.assert_array_equal(run(2.0, 2), run(10.0, 2))


def test_face_counts_and_parents():
    """Catmull–Clark and bilinear split an n-gon into n quads, then 4 a level; Loop a triangle into 4 a
    level; every refined face remembers its cage face."""
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0], [3, 0.5, 0], [0.5, 2, 0]], np.float64)
    counts = np.array([4, 5, 3, 2])  # a quad, a pentagon, a triangle and a two-corner face (left out)
    idx = np.array([0, 1, 2, 3, 1, 4, 6, 5, 2, 3, 2, 7, 0, 1])
    for level in range(4):
        for scheme in ("catmullClark", "bilinear"):
            r = refine(p, counts, idx, scheme, level)
            want = [1, 1, 1] if level == 0 else [4 * 4 ** (level - 1), 5 * 4 ** (level - 1), 3 * 4 ** (level - 1)]
            np.testing.assert_array_equal(np.bincount(r.parent, minlength=4), want + [0])
            assert len(r.counts) == refined_face_count(counts, scheme, level)
        r = refine(p, [3, 3], [0, 1, 2, 0, 2, 3], "loop", level)
        np.testing.assert_array_equal(np.bincount(r.parent), [4 ** level] * 2)


def test_face_varying_values_are_bilinear_in_each_face():
    """faceVarying values (one per corner) refine bilinearly in their face, so values that are an
    affine function of a flat square grid's points stay that function of the refined points."""
    p, counts, idx = _grid(2, 2)
    r = refine(p, counts, idx, "catmullClark", 3)
    corner_vals = p[idx, :2] * [0.5, 2.0] + [0.1, 0.2]
    fv = r.face_varying(corner_vals)
    np.testing.assert_allclose(fv, r.points[r.indices, :2] * [0.5, 2.0] + [0.1, 0.2], atol=1e-12)
    np.testing.assert_allclose(r.varying(p[:, :2]), r.points[:, :2], atol=1e-12)


def test_bad_levels_and_a_quad_under_loop_are_one_line_errors():
    for bad in (-1, 9, 1.5, True, "2"):
        with pytest.raises(ValueError, match=r"subdiv_level .* is not an integer in 0\.\.4") as exc:
            check_level(bad)
        assert "\n" not in str(exc.value)
    assert check_level(np.int64(3)) == 3
    p, counts, idx = _grid(1, 1)
    with pytest.raises(ValueError, match="loop needs triangles; face 0 has 4 corners"):
        refine(p, counts, idx, "loop", 1)
    with pytest.raises(ValueError, match="creaseSharpnesses has 3 values"):
        crease_edges([0, 1, 2], [3], [1.0, 2.0, 3.0])


def test_refining_100k_faces_once_is_fast():
    """About 100k quads refined once (400k faces) in well under a few seconds."""
    p, counts, idx = _grid(320, 316)
    p[:, 2] = np.sin(p[:, 0] * 0.1) * np.cos(p[:, 1] * 0.1)
    t0 = time.perf_counter()
    r = refine(p, counts, idx, "catmullClark", 1)
    dt = time.perf_counter() - t0
    assert len(r.counts) == 4 * 320 * 316 and dt < 3.0, dt


# -- the loader --------------------------------------------------------------------------------------


def _cube_stage(scheme: str | None = None, **kw):
    st = make_stage()
    m = add_mesh(st, "/World/Cube", _cube(), minimal=True, **kw)
    if scheme is not None:
        m.CreateSubdivisionSchemeAttr(scheme)
    return st, m


def test_cages_by_default_with_one_note_per_stage():
    """Unauthored subdivisionScheme is catmullClark (USD's fallback): loaded as the cage, one note for
    the stage (not a warning); meshes authored none get none."""
    st, _ = _cube_stage()
    add_mesh(st, "/World/Loop", ([(0, 0, 2), (1, 0, 2), (0, 1, 2)], [3], [0, 1, 2]), minimal=True).CreateSubdivisionSchemeAttr("loop")
    add_mesh(st, "/World/Poly", ([(0, 0, 3), (1, 0, 3), (0, 1, 3)], [3], [0, 1, 2]))  # authors none
    s = wsoft.load_scene(st)
    assert s.triangle_count == 12 + 1 + 1 and not s.warnings and s.subdiv_level == 0
    assert len(s.notes) == 1
    note = s.notes[0]
    assert "2 meshes are subdivision surfaces (1 catmullClark, 1 loop; 1 by USD's fallback" in note and "--subdiv-level N" in note
    st2, _ = _cube_stage("none")
    assert not wsoft.load_scene(st2).notes
    s2 = wsoft.load_scene(st, subdiv_level=2)
    assert s2.notes == [f"{s2.path}: subdiv_level 2: 2 subdivision surface meshes (1 catmullClark, 1 loop) refined, 7 cage faces into 112"]
    assert s2.triangle_count == 2 * 96 + 16 + 1 and not s2.warnings


def test_refined_cube_keeps_subset_materials_orientation_and_closes():
    from pxr import UsdGeom, UsdShade, Vt

    from wsoft.stages import add_material

    for orientation in ("rightHanded", "leftHanded"):
        st, m = _cube_stage()
        m.CreateOrientationAttr(orientation)
        red, blue = add_material(st, "/World/Looks/Red", (1, 0, 0)), add_material(st, "/World/Looks/Blue", (0, 0, 1))
        for name, faces, mat in (("a", [0, 1, 2], red), ("b", [3, 4, 5], blue)):
            sub = UsdGeom.Subset.CreateGeomSubset(m, name, UsdGeom.Tokens.face, Vt.IntArray(faces), "materialBind")
            UsdShade.MaterialBindingAPI.Apply(sub.GetPrim()).Bind(mat)
        cage, s = wsoft.load_scene(st), wsoft.load_scene(st, subdiv_level=2)
        assert s.triangle_count == 6 * 16 * 2
        np.testing.assert_array_equal(np.bincount(s.tri_face), [32] * 6)
        names = np.array([s.materials[i].path for i in s.tri_material])
        assert (names[s.tri_face < 3] == "/World/Looks/Red").all() and (names[s.tri_face >= 3] == "/World/Looks/Blue").all()
        assert s.tri_closed[0] == cage.tri_closed[0] != 0  # still closed, facing as the cage does
        np.testing.assert_allclose(s.points[:8], refine(*_cube(), "catmullClark", 2).points[:8], atol=1e-6)


def test_primvars_holes_and_time_samples_follow_the_refinement():
    """faceVarying st refined bilinearly, vertex st by the scheme (both match the flat square's xy);
    hole faces' refined faces left out; time-sampled points refined at the time loaded."""
    from pxr import Sdf, UsdGeom, Vt

    st = make_stage()
    p, counts, idx = _grid(2, 1)
    m = add_mesh(st, "/World/Strip", (p, counts, idx), minimal=True,
                 st=p[idx, :2], st_interpolation="faceVarying")
    pv = UsdGeom.PrimvarsAPI(m).CreatePrimvar("wsoft:bakedLight", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
    pv.Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)))
    m.CreateHoleIndicesAttr([1])
    m.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), 1.0)
    m.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy((p + [0, 0, 1]).astype(np.float32)), 2.0)
    a, b = wsoft.load_scene(st, time=1.0, subdiv_level=2), wsoft.load_scene(st, time=2.0, subdiv_level=2)
    assert a.triangle_count == 32 and (a.tri_face == 0).all()  # face 1 is a hole
    corners = a.points[a.triangles]
    np.testing.assert_allclose(a.tri_uv, corners[..., :2], atol=1e-6)
    np.testing.assert_allclose(a.tri_baked, corners, atol=1e-6)
    np.testing.assert_allclose(b.points, a.points + [0, 0, 1], atol=1e-6)
    assert not a.warnings


def test_interpolate_boundary_none_draws_only_faces_off_the_boundary():
    st = make_stage()
    m = add_mesh(st, "/World/Grid", _grid(3, 3), minimal=True)
    m.CreateInterpolateBoundaryAttr("none")
    q = add_quad(st, "/World/Lone", (0, 0, 2), 0.5)
    q.CreateInterpolateBoundaryAttr("none")
    s = wsoft.load_scene(st, subdiv_level=1)
    grid = s.tri_prim == s.prims.index("/World/Grid")
    assert grid.sum() == 8 and (s.tri_face[grid] == 4).all()  # the centre face, 4 quads
    assert "/World/Lone" not in [s.prims[i] for i in np.unique(s.tri_prim)]
    assert any("/World/Lone" in w and "interpolateBoundary = none" in w for w in s.warnings)


def test_bad_input_is_one_line_naming_the_file_and_prim():
    st, _ = _cube_stage("loop")
    with pytest.raises(SceneError, match="/World/Cube: subdivisionScheme loop needs triangles") as exc:
        wsoft.load_scene(st, subdiv_level=1)
    assert "\n" not in str(exc.value)
    assert wsoft.load_scene(st).triangle_count == 12  # its cage loads
    for bad in (-1, 9):
        with pytest.raises(ParameterError, match=f"subdiv_level {bad} is not an integer in 0..4"):
            wsoft.load_scene(st, subdiv_level=bad)
    st, m = _cube_stage()
    m.CreateCreaseIndicesAttr([0, 1, 2])
    m.CreateCreaseLengthsAttr([2])
    m.CreateCreaseSharpnessesAttr([1.0])
    s = wsoft.load_scene(st, subdiv_level=1)
    assert any("creaseLengths sum to 2 but creaseIndices has 3 entries; creases ignored" in w for w in s.warnings)
    m.CreateCreaseLengthsAttr([3])
    m.CreateCreaseSharpnessesAttr([float("nan")])
    with pytest.raises(SceneError, match="/World/Cube: creaseSharpnesses\\[0\\] is NaN"):
        wsoft.load_scene(st, subdiv_level=1)


def test_creases_and_corners_read_from_usd():
    """creaseIndices / creaseLengths / creaseSharpnesses and cornerIndices / cornerSharpnesses reach
    the refinement: the cube's sharp corner stays where it is, a smooth one moves."""
    st, m = _cube_stage()
    m.CreateCornerIndicesAttr([0])
    m.CreateCornerSharpnessesAttr([10.0])
    m.CreateCreaseIndicesAttr([4, 5, 7, 6, 4])  # the +Z face's outline
    m.CreateCreaseLengthsAttr([5])
    m.CreateCreaseSharpnessesAttr([10.0])
    s = wsoft.load_scene(st, subdiv_level=3)
    np.testing.assert_array_equal(s.points[0], [0, 0, 0])
    assert np.abs(s.points[3] - [1, 1, 0]).max() > 0.1
    top = s.points[:, 2] > 1 - 1e-6  # the creased face stays flat: all four of its edges infinitely sharp
    assert top.sum() == 9 * 9 and not s.warnings


def test_instanced_prototypes_are_refined_once():
    from pxr import Gf, Sdf, UsdGeom, Vt

    st = make_stage()
    pi = UsdGeom.PointInstancer.Define(st, "/World/Boxes")
    UsdGeom.Xform.Define(st, "/World/Boxes/Protos")
    add_mesh(st, "/World/Boxes/Protos/Box/Mesh", _cube(), minimal=True)
    pi.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Boxes/Protos/Box")])
    pi.CreateProtoIndicesAttr(Vt.IntArray([0, 0, 0]))
    pi.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(2 * i, 0, 0) for i in range(3)]))
    kept = wsoft.load_scene(st, instancing=True, subdiv_level=1)
    assert kept.instanced and kept.instances.prototype_triangles == 48 and kept.instances.instanced_triangles == 3 * 48
    flat = kept.flattened()
    assert flat.triangle_count == 3 * 48 and flat.subdiv_level == 1 and len(flat.notes) == 1


def test_the_cli_flag_on_a_tiny_stage(tmp_path):
    from wsoft.cli import run_captured

    path = str(tmp_path / "cube.usda")
    st = make_stage(path=path)
    add_mesh(st, "/World/Cube", box_mesh((0, 0, 1), (1, 1, 2)), minimal=True)
    add_quad(st, "/World/Ground", (0, 0, 0), 3).CreateSubdivisionSchemeAttr("none")
    add_rect_light(st, "/World/L", (0, 0, 5), 1, 1)
    st.GetRootLayer().Save()
    rc, out, err = run_captured(["plan", path, "-t", "hard"])
    assert rc == 0 and "14 triangles" in out
    assert [ln for ln in out.splitlines() if ln.startswith("note:")] == [
        f"note: {path}: 1 mesh is a subdivision surface (1 catmullClark; all by USD's fallback, subdivisionScheme unauthored; "
        "/World/Cube), loaded as its control cage: subdiv_level=N (--subdiv-level N, 1..4) refines it; subdivisionScheme = \"none\" "
        "marks a polygon mesh"]
    rc, out, err = run_captured(["plan", path, "-t", "hard", "--subdiv-level", "2"])
    assert rc == 0 and f"{6 * 32 + 2} triangles" in out and "subdiv_level 2: 1 subdivision surface mesh (1 catmullClark) refined" in out
    rc, out, err = run_captured(["plan", path, "--subdiv-level", "9"])
    assert rc == 2 and err.strip().splitlines() == [f"wsoft: error: {path}: subdiv_level 9 is not an integer in 0..4 "
                                                    "(0: the control cage; each level has 4x the faces)"]
    stats = tmp_path / "o.json"
    rc, out, err = run_captured(["render", path, "-t", "hard", "--subdiv-level", "1", "--width", "16", "--height", "12", "--device", "cpu",
                                 "--out", str(tmp_path / "o.exr"), "--stats", str(stats)])
    assert rc == 0 and json.loads(stats.read_text())["scene"]["triangles"] == 48 + 2
    assert [ln for ln in err.splitlines() if ln.startswith("note:")] == [
        f"note: {path}: subdiv_level 1: 1 subdivision surface mesh (1 catmullClark) refined, 6 cage faces into 24"]
    rc, _, err = run_captured(["render", path, "-t", "hard", "--subdiv-level", "-1", "--out", str(tmp_path / "o.exr")])
    assert rc == 2 and "subdiv_level -1 is not an integer" in err and len(err.strip().splitlines()) == 1
    for cmd in ("render", "compare", "bake"):
        rc, out, _ = run_captured([cmd, "--help"])
        assert rc == 0 and "--subdiv-level N" in out


def test_a_bake_of_a_refined_mesh_writes_the_cage_points():
    """The cage's points, at their refined positions with the refined surface's normals: a cube's
    top corners see the light above it, its bottom ones do not; texture bakes need the cage."""
    from pxr import Usd

    st = make_stage()
    add_mesh(st, "/World/Cube", box_mesh((-0.5, -0.5, 0.5), (0.5, 0.5, 1.5)), minimal=True)
    add_quad(st, "/World/Ground", (0, 0, 0), 3).CreateSubdivisionSchemeAttr("none")
    add_rect_light(st, "/World/L", (0, 0, 5), 1, 1)
    stats: dict = {}
    layer = wsoft.bake(st, "hard", subdiv_level=2, device="cpu", stats=stats)
    assert stats["meshes"]["/World/Cube"] == {"interpolation": "vertex", "normals": "refined surface", "elements": 8}
    assert stats["notes"] and "subdiv_level 2" in stats["notes"][0] and not stats["warnings"]
    baked = Usd.Stage.Open(layer)
    v = np.asarray(baked.GetPrimAtPath("/World/Cube").GetAttribute("primvars:wsoft:visibility:L").Get())
    top = box_mesh((-0.5, -0.5, 0.5), (0.5, 0.5, 1.5))[0][:, 2] > 1
    np.testing.assert_array_equal(v, np.where(top, 1.0, 0.0))
    with pytest.raises(ParameterError, match="texture_size 8 needs subdiv_level 0, not 1"):
        wsoft.bake(st, "hard", subdiv_level=1, texture_size=8, texture_dir=".", device="cpu")


def test_sequences_and_other_render_settings_load_at_the_scenes_level():
    from wsoft.pipeline.loading import load_stage
    from wsoft.pipeline.sequence import _Loader

    st, _ = _cube_stage()
    add_rect_light(st, "/World/L", (0, 0, 5), 1, 1)
    s = load_stage(st, subdiv_level=1)
    assert s.subdiv_level == 1 and s.triangle_count == 48
    sc, _ = _Loader(s, None, "auto").load(0.0)
    assert sc.subdiv_level == 1 and sc.triangle_count == 48
    sc, _ = _Loader(st, None, "auto", 2).load(0.0)
    assert sc.triangle_count == 192
