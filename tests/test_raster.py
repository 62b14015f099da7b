"""The light-view rasterizer against one BVH ray per texel, and the conservative mode."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from conftest import scene_path

import wsoft
from wsoft.lightspace.fit import fit_light_view
from wsoft.lightspace.view import DEPTH_CLEAR
from wsoft.raster.depth_map import rasterize
from wsoft.raster.raycast import raycast_depth
from wsoft.scene.device import upload_scene

CASES = [("multi_light.usda", "Rect"), ("multi_light.usda", "Sphere"), ("multi_light.usda", "Sun"), ("cutout.usda", "Light"), ("contact.usda", "Light")]


def _view(scene, light_name, size=256):
    light = scene.find_light(light_name)
    lo, hi = scene.bounds
    return fit_light_view(light, scene.points, lo, hi, size)


@pytest.mark.parametrize("file,light", CASES)
def test_depth_matches_ray_per_texel(device, file, light):
    scene = wsoft.load_scene(scene_path(file))
    ds = upload_scene(scene, device)
    view = _view(scene, light)
    a = rasterize(ds, view, alpha_tested=True).depth.numpy()
    b = raycast_depth(ds, view, alpha_tested=True).depth.numpy()
    ha, hb = a < DEPTH_CLEAR, b < DEPTH_CLEAR
    assert ha.mean() > 0.3  # the map really holds geometry
    assert (ha != hb).mean() < 1e-3  # coverage differs at most on a few edge texels
    both = ha & hb
    rel = np.abs(a - b)[both] / b[both]
    # float32 precision: worst at 80 degrees off the axis of a wide perspective view
    assert np.median(rel) < 2e-5 and np.percentile(rel, 99) < 2e-4 and rel.max() < 5e-3
    if scene.has_cutouts:
        opaque_only = rasterize(ds, view, alpha_tested=False).depth.numpy()
        assert (opaque_only < a * (1 - 1e-3)).mean() > 0.01  # the alpha test really let texels through


def _triangle_samples(scene, n_per_tri=64, seed=0):
    rng = np.random.default_rng(seed)
    p = scene.points[scene.triangles].astype(np.float64)  # [T, 3, 3]
    u = rng.random((len(p), n_per_tri, 2))
    flip = u.sum(-1) > 1
    u[flip] = 1 - u[flip]
    w = np.concatenate([1 - u.sum(-1, keepdims=True), u], -1)  # [T, n, 3]
    return np.einsum("tnk,tkd->tnd", w, p).reshape(-1, 3)


@pytest.mark.parametrize("file,light", [("multi_light.usda", "Rect"), ("multi_light.usda", "Sun"), ("contact.usda", "Light")])
def test_conservative_covers_every_touched_texel(device, file, light):
    scene = wsoft.load_scene(scene_path(file))
    ds = upload_scene(scene, device)
    view = _view(scene, light)
    std = rasterize(ds, view, alpha_tested=False).depth.numpy()
    cons = rasterize(ds, view, alpha_tested=False, conservative=True).depth.numpy()
    assert np.all(cons <= std * (1 + 1e-6))  # superset, never farther
    assert (cons < DEPTH_CLEAR).sum() > (std < DEPTH_CLEAR).sum()  # it really added texels
    # every point on every triangle lands in a texel whose conservative depth is not behind it
    pts = _triangle_samples(scene)
    if view.persp:
        pts = pts[view.to_view(pts)[:, 2] > view.near]  # texel_coords keeps only these
    v = view.to_view(pts)
    fx, fy = view.texel_coords(pts)
    tx, ty = np.floor(fx).astype(int), np.floor(fy).astype(int)
    inside = (tx >= 0) & (ty >= 0) & (tx < view.width) & (ty < view.height)
    assert inside.sum() > 1000
    d = cons[ty[inside], tx[inside]]
    assert np.all(d <= v[inside, 2] * (1 + 1e-4) + 1e-6)


@pytest.mark.parametrize("file,light", [("multi_light.usda", "Rect"), ("multi_light.usda", "Sun"), ("cutout.usda", "Light")])
def test_inner_coverage_blocks_every_ray_of_its_texels(device, file, light):
    """An inner-coverage map's texel (covered whole by one triangle, at its farthest depth) blocks
    every ray through the texel: rays at the texel's four corners (a hair inside) and its centre
    meet a surface no farther than the texel's value (alpha-tested rays: a cutout counted as a
    blocker would let some of them through its holes)."""
    import dataclasses

    scene = wsoft.load_scene(scene_path(file))
    ds = upload_scene(scene, device)
    view = _view(scene, light)
    inner = rasterize(ds, view, alpha_tested=True, inner=True).depth.numpy()
    std = rasterize(ds, view, alpha_tested=False).depth.numpy()
    hi, hs = inner < DEPTH_CLEAR, std < DEPTH_CLEAR
    assert hi.sum() > 0.5 * hs.sum()  # most covered texels are covered whole
    assert np.all(hs[hi]) and np.all(inner[hi] >= std[hi] * (1 - 1e-5))  # a subset, never nearer
    l, r, b, t = view.window
    sx, sy = (r - l) / view.width, (t - b) / view.height
    for fx, fy in ((0.0, 0.0), (-0.49, -0.49), (0.49, -0.49), (-0.49, 0.49), (0.49, 0.49)):
        shifted = dataclasses.replace(view, window=(l + fx * sx, r + fx * sx, b + fy * sy, t + fy * sy))
        ray = raycast_depth(ds, shifted, alpha_tested=True).depth.numpy()
        assert np.all(ray[hi] <= inner[hi] * (1 + 1e-4) + 1e-6), (fx, fy)


@pytest.mark.parametrize("file,light", [("contact.usda", "Light"), ("multi_light.usda", "Sun")])
def test_back_and_open_face_maps_hold_their_faces_only(device, file, light):
    """``faces=back`` holds the faces of closed surfaces turned away from the light, ``open`` every
    face of the other surfaces: each map's texel is no farther than any point of its own faces in
    it (conservative), and the ground (open) leaves the back map empty around the objects."""
    from wsoft.scene.device import face_surfaces

    scene = wsoft.load_scene(scene_path(file))
    ds = upload_scene(scene, device)
    assert ds.culled_closed > 0  # the scene has a closed surface
    view = _view(scene, light)
    maps = {f: rasterize(ds, view, alpha_tested=False, conservative=True, faces=f).depth.numpy() for f in ("back", "open")}
    hb, ho = maps["back"] < DEPTH_CLEAR, maps["open"] < DEPTH_CLEAR
    assert hb.sum() > 50 and ho.sum() > 50 and (ho & ~hb).sum() > 0.3 * ho.sum()
    tri = scene.points[scene.triangles].astype(np.float64)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    toward = (np.einsum("td,td->t", nrm, tri[:, 0] - view.origin) < 0) if view.persp else (nrm @ np.asarray(view.axes)[:, 2] < 0)
    rng = np.random.default_rng(1)
    for f, depth in maps.items():
        flags = face_surfaces(ds, view.origin if view.persp else None, f).cull.numpy()
        kept = (flags != 2) & ((flags == 0) | (toward == (flags > 0)))
        assert kept.any() and not kept.all()
        if view.persp:  # a triangle seen edge-on covers no area: the rasterizer skips it (and so may we)
            tx3, ty3 = view.texel_coords(tri.reshape(-1, 3))
            t2 = np.stack([tx3, ty3], -1).reshape(-1, 3, 2)
            e1, e2 = t2[:, 1] - t2[:, 0], t2[:, 2] - t2[:, 0]
            area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
            kept &= area > 1e-3
        u = rng.random((int(kept.sum()), 32, 2))
        u[u.sum(-1) > 1] = 1 - u[u.sum(-1) > 1]
        pts = (tri[kept, 0, None] * (1 - u.sum(-1, keepdims=True)) + tri[kept, 1, None] * u[..., :1] + tri[kept, 2, None] * u[..., 1:]).reshape(-1, 3)
        if view.persp:
            pts = pts[view.to_view(pts)[:, 2] > view.near]
        fx, fy = view.texel_coords(pts)
        tx, ty = np.floor(fx).astype(int), np.floor(fy).astype(int)
        inside = (tx >= 0) & (ty >= 0) & (tx < view.width) & (ty < view.height)
        assert inside.sum() >= 60
        z = view.to_view(pts[inside])[:, 2]
        assert np.all(depth[ty[inside], tx[inside]] <= z * (1 + 1e-4) + 1e-6), f


def test_light_inside_the_scene_stays_finite(device):
    """A point light between objects: triangles behind it are clipped at the near plane."""
    from pxr import Gf, UsdGeom, UsdLux

    from conftest import add_quad, make_stage

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 5)
    add_quad(st, "/World/Roof", (0, 0, 4), 5)  # a ceiling above the light: entirely behind it
    UsdGeom.NurbsPatch.Define(st, "/World/NotMesh")
    from pxr import Vt

    wall = UsdGeom.Mesh.Define(st, "/World/Wall")  # crosses the light's plane
    wall.CreatePointsAttr([(-1, 1, 0), (1, 1, 0), (1, 1, 4), (-1, 1, 4)])
    wall.CreateFaceVertexCountsAttr(Vt.IntArray([4]))
    wall.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 1, 2, 3]))
    lt = UsdLux.SphereLight.Define(st, "/World/Bulb")
    lt.CreateRadiusAttr(0.1)
    UsdGeom.XformCommonAPI(lt).SetTranslate(Gf.Vec3d(0, 0, 2))
    scene = wsoft.load_scene(st)
    assert any("NurbsPatch is not a Mesh" in w for w in scene.warnings)
    f = wsoft.render(scene, "hard", width=48, height=48, device=device, camera=None)
    assert np.all(np.isfinite(f.V)) and f.V.min() >= 0 and f.V.max() <= 1
    ref = wsoft.render(scene, "reference", width=48, height=48, device=device, samples=1, jitter=False)
    cov = f["A"] > 0
    assert np.mean(f.V[cov] == ref.V[cov]) > 0.97


def test_sizes_out_of_range_rejected():
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    with pytest.raises(wsoft.ParameterError, match="shadow_map_size"):
        wsoft.render(scene, "hard", width=8, height=8, device="cpu", shadow_map_size=128)
    with pytest.raises(wsoft.ParameterError, match="shadow_map_size"):
        wsoft.render(scene, "hard", width=8, height=8, device="cpu", shadow_map_size=16384)


@pytest.mark.slow
def test_8192_map_on_contact(device):
    scene = wsoft.load_scene(scene_path("contact.usda"))
    f = wsoft.render(scene, "hard", width=64, height=48, device=device, shadow_map_size=8192)
    assert np.all(np.isfinite(f.V))
    assert f.stats["memory_bytes"]["light_depth[Light]@8192.depth"] == 8192 * 8192 * 4


@pytest.mark.parametrize("light", ["Rect", "Sun"])
def test_skipping_far_faces_of_closed_meshes_changes_nothing(device, light):
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    ds = upload_scene(scene, device)
    assert ds.culled_closed > 800  # the occluders are closed: the optimisation is in play
    view = _view(scene, light, 512)
    culled = rasterize(ds, view, alpha_tested=False).depth.numpy()
    scene.tri_closed[:] = 0
    plain = rasterize(upload_scene(scene, device), view, alpha_tested=False).depth.numpy()
    assert np.array_equal(culled, plain)


@pytest.mark.parametrize("light", ["Rect", "Disk", "Sun"])
def test_margin_widens_the_view_for_soft_techniques(light):
    """Soft techniques widen the fitted window by the light's extent so every blocker of the whole light is mapped."""
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    L = scene.find_light(light)
    lo, hi = scene.bounds
    rec = scene.points[scene.triangles[scene.tri_prim == 0].ravel()]  # the ground as receivers
    tight = fit_light_view(L, rec, lo, hi, 512)
    margin = L.extent() if L.kind_name != "distant" else 0.05 * scene.diagonal
    wide = fit_light_view(L, rec, lo, hi, 512, margin=margin)
    tl, tr, tb, tt = tight.window
    wl, wr, wb, wt = wide.window
    assert wl < tl and wr > tr and wb < tb and wt > tt


def test_view_fit_reductions_by_row_blocks_equal_the_whole_array(monkeypatch):
    """The fit's caster and receiver reductions run in row blocks over the thread pool without
    keeping the transformed points: the same values as transforming every point and reducing (float32
    points, several blocks on several threads, and a window only some blocks' casters reach)."""
    from wsoft.lightspace import fit as V

    monkeypatch.setenv("WSOFT_THREADS", "3")
    rng = np.random.default_rng(7)
    p = (rng.normal(size=(300_001, 3)) * [4.0, 3.0, 2.0] + [0.0, 0.0, 9.0]).astype(np.float32)
    origin, axes = np.array([0.1, -0.2, 0.3]), np.linalg.qr(rng.normal(size=(3, 3)))[0]
    v = (p.astype(np.float64) - origin) @ axes
    lo, hi = V._frame_bounds(p, origin, axes)
    assert np.allclose(lo, v.min(axis=0), rtol=0, atol=1e-12) and np.allclose(hi, v.max(axis=0), rtol=0, atol=1e-12)
    assert np.array_equal(lo, V._frame_bounds(p, origin, axes)[0])  # the same however the blocks finish
    window, w, zmin, zmax = (-0.05, 0.02, -0.01, 0.03), 0.4, 1e-3, 8.5
    vc = V.to_frame(p, origin, axes)
    vc = vc[(vc[:, 2] > zmin) & (vc[:, 2] < zmax)]
    grow = w * (1.0 / vc[:, 2] - 1.0 / zmax)
    cx, cy = vc[:, 0] / vc[:, 2], vc[:, 1] / vc[:, 2]
    near = (cx >= window[0] - grow) & (cx <= window[1] + grow) & (cy >= window[2] - grow) & (cy <= window[3] + grow)
    assert 0 < near.sum() < len(vc)
    assert V._caster_growth(p, origin, axes, window, w, zmin, zmax) == float(grow[near].max())
    assert V._caster_growth(p, origin, axes, window, w, zmin, 1e-2) is None  # no caster in front of the receivers


def test_light_inside_a_closed_mesh_keeps_its_faces(device):
    """Skipping the far faces of closed surfaces is exact only when the light is outside them: with
    a rect light inside a closed box, every face is turned away from it and the box cast no shadow
    at all (a silent wrong answer). The box must still shadow everything outside it."""
    from conftest import add_box, add_camera, add_quad, add_rect_light, make_stage

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 6)
    add_box(st, "/World/Box", (-1, -1, 0.5), (1, 1, 2.5))
    add_rect_light(st, "/World/L", (0, 0, 1.5), 0.4, 0.4)
    add_camera(st, "/World/Cam", (4, -4, 4), (0, 0, 0))
    scene = wsoft.load_scene(st)
    assert upload_scene(scene, device).culled_closed == 12  # the box is closed: culling would apply
    kw = dict(width=96, height=72, device=device)
    hard = wsoft.render(scene, "hard", shadow_map_size=2048, **kw)
    ref = wsoft.render(scene, "reference", samples=1, jitter=False, **kw)
    cov = hard["A"] > 0
    assert (ref.V[cov] == 0).mean() > 0.5  # the outside of the box is dark
    assert np.mean(hard.V[cov] == ref.V[cov]) > 0.99


@pytest.mark.parametrize("file,light", [("multi_light.usda", "Rect"), ("multi_light.usda", "Sun"), ("cutout.usda", "Light"), ("contact.usda", "Light")])
def test_points_projected_first_and_the_branch_free_loop_change_no_texel(device, file, light):
    """Projecting every point once first (:func:`project_points`) gives the map that projecting each
    triangle's corners gives, and a masked fragment's branch-free flat loop the map of the branching
    one (the same fragment, unmasked), bit for bit; near-plane clipping included (a light in the scene)."""
    from dataclasses import replace

    from wsoft.raster.depth_map import DepthTarget, depth_min
    from wsoft.raster.rasterizer import Rasterizer, make_rasterizer
    from wsoft.scene.device import view_surfaces

    scene = wsoft.load_scene(scene_path(file))
    ds = upload_scene(scene, device)
    view = _view(scene, light, 512)
    if file == "contact.usda":  # the near plane pushed in among the corners: triangles cross it and are clipped
        depth = (scene.points - view.origin) @ view.axes[:, 2]
        corners = depth[np.asarray(scene.triangles).reshape(-1, 3)]
        view = replace(view, near=float(np.percentile(corners, 10)))
        assert ((corners.min(1) < view.near) & (corners.max(1) >= view.near)).sum() > 20
    surfaces = view_surfaces(ds, view.origin if view.persp else None)
    alpha = bool(scene.has_cutouts)
    masked = make_rasterizer(view, depth_min, alpha=alpha)
    branching = Rasterizer(masked.persp, replace(masked.spec, masked=False), False, alpha)
    differs = masked.kernel(False, True, False, True).module.name != branching.kernel(False, True, False, True).module.name
    assert masked.spec.masked and differs == (not view.persp)  # a perspective view's loop branches either way

    def draw(r, preproject):
        t = DepthTarget()
        t.depth = wp.empty((view.height, view.width), dtype=float, device=device)
        r.run(ds.points, ds.indices, surfaces, view, t, device, initialized=False, preproject=preproject)
        return t.depth.numpy()

    first = draw(masked, True)
    assert (first < DEPTH_CLEAR).mean() > 0.2
    assert np.array_equal(first, draw(masked, False))
    assert np.array_equal(first, draw(branching, True))
